//! The text syntax of `--route` and `--add` (parsed here, checked against the scene's
//! objects in `layout`):
//!
//! - route: `[NAME=]P;P;...` (≥ 2 waypoints), `P = x,y[,z][@yaw[,pitch,roll]]`, world
//!   units and degrees;
//! - add: `KIND@x,y[,yaw]`, KIND `crate`, `barrel` or `crane` (articulated).

use crate::SceneError;
use std::str::FromStr;

/// One waypoint of a route: the object's origin (z = height above the ground) and, when
/// given, its orientation there in degrees (yaw about +z, pitch about +y, roll about +x).
#[derive(Clone, Debug, PartialEq)]
pub struct Waypoint {
    pub pos: [f32; 3],
    pub angles_deg: Option<[f32; 3]>,
}

/// A parsed `--route`: which object (None: the preset's moving vehicle) and its waypoints.
#[derive(Clone, Debug, PartialEq)]
pub struct RouteSpec {
    pub object: Option<String>,
    pub waypoints: Vec<Waypoint>,
    /// The option's text as given, for error messages and `objects.json`.
    pub text: String,
}

/// The kinds of object `--add` can place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PropKind {
    /// A wooden toy crate with printed markings.
    Crate,
    /// An upright striped toy barrel.
    Barrel,
    /// A wooden toy crane whose boom and bucket turn (articulated, `joints`).
    Crane,
}

impl PropKind {
    pub fn name(self) -> &'static str {
        match self {
            PropKind::Crate => "crate",
            PropKind::Barrel => "barrel",
            PropKind::Crane => "crane",
        }
    }
}

/// A parsed `--add`: a parked object of `kind` at `(x, y)` on the ground, heading `yaw_deg`
/// (a crane's boom and bucket still move about their joints).
#[derive(Clone, Debug, PartialEq)]
pub struct AddSpec {
    pub kind: PropKind,
    pub x: f32,
    pub y: f32,
    pub yaw_deg: f32,
    pub text: String,
}

fn bad(option: &str, text: &str, msg: impl std::fmt::Display) -> SceneError {
    SceneError::Argument(format!("{option} `{text}`: {msg}"))
}

/// Comma-separated finite numbers; `what` names the list in errors.
fn numbers(s: &str, what: &str) -> Result<Vec<f32>, String> {
    s.split(',')
        .map(|v| match v.trim().parse::<f32>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(format!("{what}: `{}` is not a finite number", v.trim())),
        })
        .collect()
}

fn waypoint(s: &str) -> Result<Waypoint, String> {
    let (pos, angles) = match s.split_once('@') {
        Some((p, a)) => (p, Some(a)),
        None => (s, None),
    };
    let p = numbers(pos, "position")?;
    let pos = match p[..] {
        [x, y] => [x, y, 0.0],
        [x, y, z] if z >= 0.0 => [x, y, z],
        [_, _, z] => return Err(format!("z = {z} is below the ground (z ≥ 0)")),
        _ => {
            return Err(format!(
                "position needs x,y or x,y,z, got {} numbers",
                p.len()
            ))
        }
    };
    let angles_deg = match angles.map(|a| numbers(a, "angles")).transpose()? {
        None => None,
        Some(a) => match a[..] {
            [yaw] => Some([yaw, 0.0, 0.0]),
            [yaw, pitch, roll] => Some([yaw, pitch, roll]),
            _ => {
                return Err(format!(
                    "after @ give yaw or yaw,pitch,roll, got {} numbers",
                    a.len()
                ))
            }
        },
    };
    Ok(Waypoint { pos, angles_deg })
}

impl FromStr for RouteSpec {
    type Err = SceneError;
    fn from_str(text: &str) -> Result<Self, SceneError> {
        let (object, list) = match text.split_once('=') {
            Some((name, rest)) => (Some(name.trim()), rest),
            None => (None, text),
        };
        if object == Some("") {
            return Err(bad("--route", text, "empty object name before `=`"));
        }
        let waypoints = list
            .split(';')
            .enumerate()
            .map(|(i, p)| {
                waypoint(p).map_err(|m| bad("--route", text, format!("waypoint {}: {m}", i + 1)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        if waypoints.len() < 2 {
            return Err(bad(
                "--route",
                text,
                "needs at least 2 waypoints separated by `;`",
            ));
        }
        Ok(Self {
            object: object.map(str::to_string),
            waypoints,
            text: text.to_string(),
        })
    }
}

impl FromStr for AddSpec {
    type Err = SceneError;
    fn from_str(text: &str) -> Result<Self, SceneError> {
        let (kind, at) = text
            .split_once('@')
            .ok_or_else(|| bad("--add", text, "expected KIND@x,y[,yaw]"))?;
        let kind = match kind.trim().to_ascii_lowercase().as_str() {
            "crate" => PropKind::Crate,
            "barrel" => PropKind::Barrel,
            "crane" => PropKind::Crane,
            k => {
                return Err(bad(
                    "--add",
                    text,
                    format!("unknown kind `{k}` (crate, barrel or crane)"),
                ))
            }
        };
        let v = numbers(at, "position").map_err(|m| bad("--add", text, m))?;
        let (x, y, yaw_deg) = match v[..] {
            [x, y] => (x, y, 0.0),
            [x, y, yaw] => (x, y, yaw),
            _ => {
                return Err(bad(
                    "--add",
                    text,
                    format!("expected x,y or x,y,yaw after @, got {} numbers", v.len()),
                ))
            }
        };
        Ok(Self {
            kind,
            x,
            y,
            yaw_deg,
            text: text.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn good_routes_parse() {
        let r: RouteSpec = "crate=0,0; 0.5,-0.2,0.1@90 ;1,1,0@-45,10,5"
            .parse()
            .unwrap();
        assert_eq!(r.object.as_deref(), Some("crate"));
        assert_eq!(
            r.waypoints,
            [
                Waypoint {
                    pos: [0.0, 0.0, 0.0],
                    angles_deg: None
                },
                Waypoint {
                    pos: [0.5, -0.2, 0.1],
                    angles_deg: Some([90.0, 0.0, 0.0])
                },
                Waypoint {
                    pos: [1.0, 1.0, 0.0],
                    angles_deg: Some([-45.0, 10.0, 5.0])
                },
            ]
        );
        let r: RouteSpec = "-0.9,-0.5;0.7,0.7".parse().unwrap();
        assert_eq!((r.object, r.waypoints.len()), (None, 2));
    }

    #[test]
    fn bad_routes_say_what_is_wrong() {
        for (spec, want) in [
            ("0,0", "at least 2 waypoints"),
            (
                "a=0,0;1,x",
                "waypoint 2: position: `x` is not a finite number",
            ),
            ("0,0;1,nan", "not a finite number"),
            ("0,0;1", "x,y or x,y,z"),
            ("0,0;1,1,1,1", "x,y or x,y,z"),
            ("0,0;1,1,-0.1", "below the ground"),
            ("0,0;1,1@1,2", "yaw or yaw,pitch,roll"),
            ("0,0;1,1@", "angles"),
            ("=0,0;1,1", "empty object name"),
            ("0,0;;1,1", "waypoint 2"),
        ] {
            let e = spec.parse::<RouteSpec>().unwrap_err().to_string();
            assert!(e.contains("--route") && e.contains(want), "{spec}: {e}");
        }
    }

    #[test]
    fn adds_parse_and_refuse_nonsense() {
        let a: AddSpec = "crate@0.3,-0.4,30".parse().unwrap();
        assert_eq!(
            (a.kind, a.x, a.y, a.yaw_deg),
            (PropKind::Crate, 0.3, -0.4, 30.0)
        );
        let a: AddSpec = "Barrel@0,0".parse().unwrap();
        assert_eq!((a.kind, a.yaw_deg), (PropKind::Barrel, 0.0));
        for (spec, want) in [
            ("crate", "KIND@x,y"),
            ("piano@0,0", "unknown kind `piano`"),
            ("crate@0", "x,y or x,y,yaw"),
            ("crate@0,y", "not a finite number"),
        ] {
            let e = spec.parse::<AddSpec>().unwrap_err().to_string();
            assert!(e.contains("--add") && e.contains(want), "{spec}: {e}");
        }
    }
}
