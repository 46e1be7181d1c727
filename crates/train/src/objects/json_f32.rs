//! Floats that JSON cannot hold: `serde_json` writes a non-finite `f32` (a static test
//! that no view could measure reads `inf`) as `null` and cannot read it back as a number.
//! These helpers write such a value as the text `"inf"`, `"-inf"` or `"NaN"` and read both
//! forms, so the start's reports round-trip through a checkpoint's metadata exactly. Use
//! with `#[serde(with = "json_f32")]`, or `json_f32::option` for an `Option<f32>`.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Repr {
    Number(f32),
    Text(String),
}

fn to_repr(v: f32) -> Repr {
    if v.is_finite() {
        Repr::Number(v)
    } else {
        Repr::Text(v.to_string())
    }
}

fn from_repr<E: serde::de::Error>(r: Repr) -> Result<f32, E> {
    match r {
        Repr::Number(v) => Ok(v),
        Repr::Text(t) => t
            .parse()
            .map_err(|_| E::custom(format!("`{t}` is not a number"))),
    }
}

pub fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
    to_repr(*v).serialize(s)
}

pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    from_repr(Repr::deserialize(d)?)
}

pub mod option {
    use super::*;

    pub fn serialize<S: Serializer>(v: &Option<f32>, s: S) -> Result<S::Ok, S::Error> {
        v.map(to_repr).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f32>, D::Error> {
        Option::<Repr>::deserialize(d)?.map(from_repr).transpose()
    }
}

#[cfg(test)]
mod tests {
    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct T {
        #[serde(with = "super")]
        a: f32,
        #[serde(with = "super::option", default)]
        b: Option<f32>,
    }

    #[test]
    fn non_finite_values_round_trip() {
        for a in [1.5, f32::INFINITY, f32::NEG_INFINITY] {
            for b in [None, Some(-2.0), Some(f32::INFINITY)] {
                let text = serde_json::to_string(&T { a, b }).unwrap();
                assert_eq!(
                    serde_json::from_str::<T>(&text).unwrap(),
                    T { a, b },
                    "{text}"
                );
            }
        }
        let nan: T = serde_json::from_str(r#"{"a":"NaN"}"#).unwrap();
        assert!(nan.a.is_nan() && nan.b.is_none());
        assert!(serde_json::from_str::<T>(r#"{"a":"wide"}"#).is_err());
    }
}
