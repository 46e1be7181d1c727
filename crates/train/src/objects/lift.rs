//! Lifting an object's mask into 3D from the static reconstruction: the background's depth
//! is read in a thin band around the mask (what the object stands in front of, excluding
//! other objects), and the mask's pixels are back-projected there, each with its pixel's
//! colour, as the object's first Gaussians. The object's size and distance along the
//! viewing rays are only fixed up to one common factor by a monocular video; `gauge.rs`
//! fixes it later from occlusions, so this depth only has to be roughly right.

use crate::init::SH_C0;
use crate::model::{inverse_sigmoid, GaussianModel, SH_FLOATS};
use rand::Rng;
use splat::{Camera, Colors, Gaussians, Rasterizer, RenderOptions};

/// A depth map: camera z per pixel (`H·W`), NaN where the render is mostly transparent.
#[derive(Clone, Debug, Default)]
pub struct DepthMap {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<f32>,
}

impl DepthMap {
    pub fn at(&self, x: u32, y: u32) -> f32 {
        self.depth[(y * self.width + x) as usize]
    }
}

/// Camera depth per pixel of the Gaussians `means/quats/scales/opacity` seen from `cam`:
/// the depth of the strongest contributor (largest `T·α`) where it carries at least
/// `STRONG` of the pixel, else the alpha-weighted mean depth where the pixel is at least
/// `OPAQUE` covered, else NaN. The strongest contributor, unlike the mean, is not pulled
/// towards the camera by faint floaters in front of a surface; the mean covers an early,
/// still translucent model.
pub fn render_depth(
    raster: &mut Rasterizer,
    means: &[f32],
    quats: &[f32],
    scales: &[f32],
    opacity_logits: &[f32],
    cam: &Camera,
) -> Result<DepthMap, splat::SplatError> {
    const STRONG: f32 = 0.2;
    const OPAQUE: f32 = 0.3;
    let z: Vec<f32> = means
        .chunks_exact(3)
        .flat_map(|m| [cam.to_camera([m[0], m[1], m[2]])[2]; 3])
        .collect();
    let g = Gaussians {
        means,
        quats,
        scales,
        opacity_logits,
        colors: Colors::Rgb(&z),
    };
    let opts = RenderOptions {
        topk: 1,
        ..RenderOptions::default()
    };
    let out = raster.forward(&g, cam, &opts)?;
    let depth = (0..out.alpha.len())
        .map(|p| {
            let (id, w, a) = (out.topk_ids[p], out.topk_weights[p], out.alpha[p]);
            if id != u32::MAX && w >= STRONG {
                out.depths[id as usize]
            } else if a >= OPAQUE {
                out.image[p * 3] / a
            } else {
                f32::NAN
            }
        })
        .collect();
    Ok(DepthMap {
        width: cam.width,
        height: cam.height,
        depth,
    })
}

/// Pixels of `id` in an ID map, and their bounding box `[x0, y0, x1, y1]` (inclusive).
pub fn mask_pixels(id_map: &[u8], width: u32, id: u8) -> (Vec<(u32, u32)>, [u32; 4]) {
    let mut px = Vec::new();
    let mut bb = [u32::MAX, u32::MAX, 0, 0];
    for (k, &v) in id_map.iter().enumerate() {
        if v == id {
            let (x, y) = (k as u32 % width, k as u32 / width);
            px.push((x, y));
            bb = [bb[0].min(x), bb[1].min(y), bb[2].max(x), bb[3].max(y)];
        }
    }
    (px, bb)
}

/// Median background depth in the band of `ring` pixels around the mask of `id`, over
/// background pixels only (other objects are not what this one stands in front of).
pub fn ring_depth(depth: &DepthMap, id_map: &[u8], id: u8, ring: u32) -> Option<f32> {
    let (w, h) = (depth.width as i64, depth.height as i64);
    let r = ring.max(1) as i64;
    let mut near = vec![false; id_map.len()];
    for (k, &v) in id_map.iter().enumerate() {
        if v != id {
            continue;
        }
        let (x, y) = (k as i64 % w, k as i64 / w);
        for dy in -r..=r {
            for dx in -r..=r {
                let (u, v) = (x + dx, y + dy);
                if u >= 0 && v >= 0 && u < w && v < h {
                    near[(v * w + u) as usize] = true;
                }
            }
        }
    }
    let mut ds: Vec<f32> = (0..id_map.len())
        .filter(|&k| near[k] && id_map[k] == crate::objects::NO_OBJECT)
        .map(|k| depth.depth[k])
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if ds.is_empty() {
        return None;
    }
    let mid = ds.len() / 2;
    ds.select_nth_unstable_by(mid, f32::total_cmp);
    Some(ds[mid])
}

/// The world point at camera depth `z` on the ray through pixel position (u, v).
pub fn unproject(cam: &Camera, u: f32, v: f32, z: f32) -> [f32; 3] {
    let pc = [(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z];
    let m = &cam.viewmat;
    let d = [pc[0] - m[0][3], pc[1] - m[1][3], pc[2] - m[2][3]];
    std::array::from_fn(|k| m[0][k] * d[0] + m[1][k] * d[1] + m[2][k] * d[2])
}

/// What [`lift`] needs of one view.
pub struct LiftInput<'a> {
    pub cam: &'a Camera,
    /// `H·W·3` RGB in [0, 1].
    pub image: &'a [f32],
    pub id_map: &'a [u8],
    pub id: u8,
    /// Camera depth to lift to.
    pub depth: f32,
}

/// World-space Gaussians on the mask's pixels at `depth` (± `thickness` × the mask's width
/// in world units, uniformly), at most `max_points` (a regular pixel stride), coloured by
/// their pixels, isotropic with the size of the pixel stride's footprint, opacity 0.5.
pub fn lift(
    inp: &LiftInput,
    max_points: usize,
    thickness: f32,
    rng: &mut impl Rng,
) -> GaussianModel {
    let (px, bb) = mask_pixels(inp.id_map, inp.cam.width, inp.id);
    let stride = ((px.len() as f32 / max_points.max(1) as f32).sqrt().ceil() as u32).max(1);
    let chosen: Vec<(u32, u32)> = px
        .into_iter()
        .filter(|&(x, y)| x % stride == 0 && y % stride == 0)
        .collect();
    let width_world = (bb[2] + 1 - bb[0]) as f32 * inp.depth / inp.cam.fx;
    let footprint = stride as f32 * inp.depth / inp.cam.fx;
    let mut m = GaussianModel::default();
    for &(x, y) in &chosen {
        let jitter = thickness * width_world * (rng.gen::<f32>() - 0.5);
        let z = (inp.depth + jitter).max(0.05 * inp.depth);
        let u = x as f32 + 0.5;
        let v = y as f32 + 0.5;
        m.means.extend(unproject(inp.cam, u, v, z));
        m.quats.extend([1.0, 0.0, 0.0, 0.0]);
        m.log_scales
            .extend([(0.7 * footprint * z / inp.depth).ln(); 3]);
        m.opacity_logits.push(inverse_sigmoid(0.5));
        let k = ((y * inp.cam.width + x) * 3) as usize;
        let mut sh = [0.0f32; SH_FLOATS];
        for (s, &v) in sh.iter_mut().zip(&inp.image[k..k + 3]) {
            *s = (v - 0.5) / SH_C0;
        }
        m.sh.extend(sh);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn cam() -> Camera {
        Camera {
            width: 32,
            height: 24,
            fx: 30.0,
            fy: 30.0,
            cx: 16.0,
            cy: 12.0,
            viewmat: [
                [1., 0., 0., 0.1],
                [0., 1., 0., -0.2],
                [0., 0., 1., 2.0],
                [0., 0., 0., 1.],
            ],
        }
    }

    #[test]
    fn unprojected_points_project_back() {
        let c = cam();
        let p = unproject(&c, 7.5, 19.5, 1.7);
        let (px, z) = c.project(p).unwrap();
        assert!(
            (px[0] - 7.5).abs() < 1e-4 && (px[1] - 19.5).abs() < 1e-4 && (z - 1.7).abs() < 1e-5
        );
    }

    #[test]
    fn ring_depth_reads_the_background_around_the_mask() {
        let c = cam();
        let mut id_map = vec![255u8; 32 * 24];
        let mut depth = vec![5.0f32; 32 * 24];
        for y in 8..12 {
            for x in 10..14 {
                id_map[y * 32 + x] = 3;
                depth[y * 32 + x] = 1.0; // what is behind the mask does not count
            }
        }
        // Another object beside it does not count either.
        for y in 8..12 {
            id_map[y * 32 + 14] = 7;
            depth[y * 32 + 14] = 0.5;
        }
        let dm = DepthMap {
            width: c.width,
            height: c.height,
            depth,
        };
        assert_eq!(ring_depth(&dm, &id_map, 3, 2), Some(5.0));
        assert_eq!(ring_depth(&dm, &id_map, 9, 2), None);
    }

    #[test]
    fn lifted_gaussians_cover_the_mask_at_the_depth() {
        let c = cam();
        let mut id_map = vec![255u8; 32 * 24];
        let image = vec![0.25f32; 32 * 24 * 3];
        for y in 4..20 {
            for x in 4..28 {
                id_map[y * 32 + x] = 1;
            }
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let inp = LiftInput {
            cam: &c,
            image: &image,
            id_map: &id_map,
            id: 1,
            depth: 2.0,
        };
        let m = lift(&inp, 100, 0.0, &mut rng);
        assert!(m.len() <= 100 && m.len() >= 50, "{}", m.len());
        m.validate().unwrap();
        for k in 0..m.len() {
            let p = [m.means[k * 3], m.means[k * 3 + 1], m.means[k * 3 + 2]];
            let (px, z) = c.project(p).unwrap();
            assert!((z - 2.0).abs() < 1e-4);
            assert_eq!(id_map[px[1] as usize * 32 + px[0] as usize], 1);
        }
        assert!((m.sh[0] - (0.25 - 0.5) / SH_C0).abs() < 1e-6);
    }
}
