//! The methods `compare` puts side by side, in display order: every table row, plot line
//! and figure column follows this list, so a fourth method is one more entry of
//! [`METHODS`], not a special case elsewhere.

use serde::{Deserialize, Serialize};

/// How a method's run is trained by `semdynreg train`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Training {
    /// The SemDynReg loss on (`--reg`) or off (`--no-reg`).
    pub reg: bool,
    /// Each object of the ID maps as a rigid body (`--objects`).
    pub objects: bool,
    /// The key of the method whose checkpoint at the regularizer's start this one forks
    /// from (`train --fork`), instead of repeating the schedule both share.
    pub fork_from: Option<&'static str>,
}

/// One compared method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Method {
    /// Its key in `results.json`, in file names and in `config`.
    pub key: &'static str,
    /// Its run folder under `compare --out`.
    pub folder: &'static str,
    pub training: Training,
    /// What the tables, plots and figure call it.
    pub display: &'static str,
}

/// Every method, in the order the report shows them.
pub static METHODS: [Method; 3] = [
    Method {
        key: "baseline",
        folder: "baseline",
        training: Training {
            reg: false,
            objects: false,
            fork_from: None,
        },
        display: "baseline",
    },
    Method {
        key: "semdynreg",
        folder: "semdynreg",
        training: Training {
            reg: true,
            objects: false,
            fork_from: Some("baseline"),
        },
        display: "SemDynReg (paper)",
    },
    Method {
        key: "rigid",
        folder: "rigid",
        training: Training {
            reg: false,
            objects: true,
            fork_from: None,
        },
        display: "rigid objects",
    },
];

/// The method with this key.
pub fn method(key: &str) -> Option<&'static Method> {
    METHODS.iter().find(|m| m.key == key)
}

/// A method as `results.json` lists it (`methods`): its key and display name.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MethodName {
    pub key: String,
    pub name: String,
}

impl From<&Method> for MethodName {
    fn from(m: &Method) -> Self {
        Self {
            key: m.key.into(),
            name: m.display.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_unique_and_forks_point_at_earlier_methods() {
        for (i, m) in METHODS.iter().enumerate() {
            assert_eq!(method(m.key), Some(m), "{} is listed once", m.key);
            if let Some(from) = m.training.fork_from {
                let j = METHODS.iter().position(|o| o.key == from).unwrap();
                // `compare` trains in list order: the run forked from must exist by then.
                assert!(j < i, "{} forks from a later method", m.key);
            }
        }
    }
}
