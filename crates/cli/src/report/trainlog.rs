//! Reads a run's training log (JSON Lines, one object per record) into curves for the
//! report's training plots. Records without an iteration number, or without the wanted
//! key, are skipped, so the same reader serves per-iteration and periodic-eval records.

use anyhow::{Context, Result};
use serde_json::{Map, Value};
use std::path::Path;

/// Keys accepted as the iteration number, in order of preference.
const ITER_KEYS: [&str; 3] = ["iter", "iteration", "step"];

/// The parsed records of one log.
#[derive(Clone, Debug, Default)]
pub struct TrainLog {
    pub records: Vec<Map<String, Value>>,
}

impl TrainLog {
    /// Parses a JSONL file; a malformed line is an error naming the file and line.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading training log {}", path.display()))?;
        let mut records = Vec::new();
        for (i, line) in text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
        {
            let value: Value = serde_json::from_str(line)
                .with_context(|| format!("{}:{}: not a JSON record", path.display(), i + 1))?;
            if let Value::Object(map) = value {
                records.push(map);
            }
        }
        Ok(Self { records })
    }

    /// `(iteration, value)` for every record holding a finite number under `key`.
    pub fn series(&self, key: &str) -> Vec<(f64, f64)> {
        self.records
            .iter()
            .filter_map(|r| {
                let iter = ITER_KEYS.iter().find_map(|k| r.get(*k)?.as_f64())?;
                let v = r.get(key)?.as_f64()?;
                v.is_finite().then_some((iter, v))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_series_and_skips_other_records() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("log.jsonl");
        std::fs::write(
            &p,
            "{\"iter\": 1, \"loss\": 0.5, \"psnr\": 12.0}\n\n{\"iter\": 2, \"loss\": 0.4}\n\
             {\"event\": \"eval\", \"iter\": 2, \"test_psnr\": 14.0}\n{\"note\": \"no iter\", \"loss\": 9}\n",
        )
        .unwrap();
        let log = TrainLog::read(&p).unwrap();
        assert_eq!(log.series("loss"), vec![(1.0, 0.5), (2.0, 0.4)]);
        assert_eq!(log.series("psnr"), vec![(1.0, 12.0)]);
        assert_eq!(log.series("test_psnr"), vec![(2.0, 14.0)]);
    }

    #[test]
    fn malformed_line_names_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.jsonl");
        std::fs::write(&p, "{\"iter\": 1}\n{oops\n").unwrap();
        let err = format!("{:#}", TrainLog::read(&p).unwrap_err());
        assert!(err.contains("bad.jsonl:2"), "{err}");
    }
}
