// The viewer's orbit camera: it circles a target about the scene's up axis. Poses are in
// the renderer's convention (OpenCV axes: x right, y down, z forward; the rotation maps
// camera to world, as a quaternion [x, y, z, w]).

const add = (a, b) => a.map((v, i) => v + b[i]);
const sub = (a, b) => a.map((v, i) => v - b[i]);
const mul = (a, s) => a.map((v) => v * s);
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [
  a[1] * b[2] - a[2] * b[1],
  a[2] * b[0] - a[0] * b[2],
  a[0] * b[1] - a[1] * b[0],
];
const normalize = (a) => mul(a, 1 / Math.hypot(...a));

// Quaternion [x, y, z, w] of the rotation whose columns are x, y, z (Shepperd's method).
export function quatFromAxes(x, y, z) {
  const m = [
    [x[0], y[0], z[0]],
    [x[1], y[1], z[1]],
    [x[2], y[2], z[2]],
  ];
  const tr = m[0][0] + m[1][1] + m[2][2];
  let q;
  if (tr > 0) {
    const s = Math.sqrt(tr + 1) * 2;
    q = [(m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, s / 4];
  } else if (m[0][0] > m[1][1] && m[0][0] > m[2][2]) {
    const s = Math.sqrt(1 + m[0][0] - m[1][1] - m[2][2]) * 2;
    q = [s / 4, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s];
  } else if (m[1][1] > m[2][2]) {
    const s = Math.sqrt(1 + m[1][1] - m[0][0] - m[2][2]) * 2;
    q = [(m[0][1] + m[1][0]) / s, s / 4, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s];
  } else {
    const s = Math.sqrt(1 + m[2][2] - m[0][0] - m[1][1]) * 2;
    q = [(m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, s / 4, (m[1][0] - m[0][1]) / s];
  }
  return mul(q, 1 / Math.hypot(...q));
}

// The camera's forward axis (its z column) from a quaternion [x, y, z, w].
export function forwardOf([x, y, z, w]) {
  return [2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)];
}

export class Orbit {
  constructor(target, up, radius) {
    this.target = [...target];
    this.up = normalize(up);
    // Two horizontal axes: yaw 0 looks from e1, yaw π/2 from e2.
    const any = Math.abs(this.up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    this.e1 = normalize(cross(this.up, any));
    this.e2 = cross(this.up, this.e1);
    this.yaw = 0;
    this.pitch = 0.4;
    this.radius = radius;
  }

  position() {
    const c = Math.cos(this.pitch);
    const dir = add(
      add(mul(this.e1, c * Math.cos(this.yaw)), mul(this.e2, c * Math.sin(this.yaw))),
      mul(this.up, Math.sin(this.pitch)),
    );
    return add(this.target, mul(dir, this.radius));
  }

  // Camera axes looking at the target with the scene's up on screen.
  axes() {
    const f = normalize(sub(this.target, this.position()));
    const x = normalize(cross(f, this.up));
    return { x, y: cross(f, x), z: f };
  }

  pose() {
    const { x, y, z } = this.axes();
    return { position: this.position(), rotation: quatFromAxes(x, y, z) };
  }

  // Continues orbiting from a given camera: the target moves onto its optical axis at
  // the current distance, so the first drag starts from exactly what is on screen.
  lookFrom(position, rotation) {
    const f = normalize(forwardOf(rotation));
    const d = Math.max(Math.hypot(...sub(this.target, position)), 1e-3);
    this.target = add(position, mul(f, d));
    const dir = mul(f, -1);
    this.pitch = Math.asin(Math.max(-1, Math.min(1, dot(dir, this.up))));
    this.yaw = Math.atan2(dot(dir, this.e2), dot(dir, this.e1));
    this.radius = d;
  }

  rotate(dx, dy) {
    this.yaw -= dx * 0.008;
    this.pitch = Math.max(-1.5, Math.min(1.5, this.pitch + dy * 0.008));
  }

  zoom(factor) {
    this.radius = Math.max(1e-3, this.radius * factor);
  }

  // Moves the target with the image: `dx, dy` pixels at focal length `focal`.
  pan(dx, dy, focal) {
    const { x, y } = this.axes();
    const s = this.radius / focal;
    this.target = add(this.target, add(mul(x, -dx * s), mul(y, -dy * s)));
  }

  toParam() {
    return [this.yaw, this.pitch, this.radius, ...this.target].map((v) => v.toFixed(4)).join(",");
  }

  // Reads `yaw,pitch,radius,tx,ty,tz`; false (and unchanged) when malformed.
  fromParam(s) {
    const v = s.split(",").map(Number);
    if (v.length !== 6 || v.some((x) => !Number.isFinite(x))) return false;
    [this.yaw, this.pitch, this.radius] = v;
    this.target = v.slice(3);
    return true;
  }
}
