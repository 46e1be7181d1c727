//! Dictionary relevance and per-mask object IDs (paper Sec. 3.1, docs/architecture.md
//! "SemDynReg" item 3).
//!
//! The paper writes the relevance of prompt `i` for a feature `F(v)` as
//! `exp(F·eᵢ) / (exp(F·eᵢ) + exp(F·e_c))`, minimized over the canonical phrases `c`.
//! Following LERF (Kerr et al. 2023, Sec. 3.3) and LangSplat, the dot products are scaled
//! by a temperature of 10 before the pairwise softmax, a constant the paper omits:
//! `rᵢ(v) = min_c softmax(10·[F(v)·eᵢ, F(v)·e_c])₀`.
//! The masks handed to us are non-overlapping and every pixel of a mask shares the mask's
//! feature, so relevance is computed once per mask and painted afterwards (`crate::idmap`).

use thiserror::Error;

/// LERF's softmax temperature (multiplies the cosine similarities).
pub const LERF_TEMPERATURE: f32 = 10.0;

/// Default acceptance threshold τ on `max rᵢ` (docs/architecture.md item 3).
pub const DEFAULT_TAU: f32 = 0.5;

/// The canonical (negative) phrases of LERF, encoded next to the dictionary.
pub const CANONICAL_PHRASES: [&str; 4] = ["object", "things", "stuff", "texture"];

/// Object IDs are stored as 8-bit values with 255 reserved for background, so at most
/// 255 dictionary entries fit.
pub const MAX_DICTIONARY: usize = 255;

/// Errors of the relevance step.
#[derive(Debug, Error)]
pub enum RelevanceError {
    #[error("the dictionary is empty: pass at least one prompt (e.g. --dict \"white SUV\")")]
    EmptyDictionary,
    #[error("no canonical phrase embeddings: relevance needs at least one (LERF uses {CANONICAL_PHRASES:?})")]
    NoCanonical,
    #[error("the dictionary has {0} prompts; object IDs are 8-bit with 255 = background, so at most {MAX_DICTIONARY} fit")]
    TooManyPrompts(usize),
    #[error("embedding dimension mismatch: {what} has length {got}, expected {expected}")]
    DimMismatch {
        what: String,
        got: usize,
        expected: usize,
    },
}

/// L2-normalized text embeddings: one per dictionary prompt (object `i` ↔ prompt `i`) and
/// one per canonical phrase.
#[derive(Debug, Clone)]
pub struct DictionaryEmbeddings {
    pub prompts: Vec<Vec<f32>>,
    pub canonical: Vec<Vec<f32>>,
}

impl DictionaryEmbeddings {
    /// Checks the shapes once so the per-mask loop can index freely.
    pub fn validate(&self) -> Result<usize, RelevanceError> {
        if self.prompts.is_empty() {
            return Err(RelevanceError::EmptyDictionary);
        }
        if self.prompts.len() > MAX_DICTIONARY {
            return Err(RelevanceError::TooManyPrompts(self.prompts.len()));
        }
        if self.canonical.is_empty() {
            return Err(RelevanceError::NoCanonical);
        }
        let dim = self.prompts[0].len();
        let all = self
            .prompts
            .iter()
            .enumerate()
            .map(|(i, e)| (format!("prompt {i}"), e));
        let canon = self
            .canonical
            .iter()
            .enumerate()
            .map(|(i, e)| (format!("canonical phrase {i}"), e));
        for (what, e) in all.chain(canon) {
            check_dim(&what, e.len(), dim)?;
        }
        Ok(dim)
    }
}

fn check_dim(what: &str, got: usize, expected: usize) -> Result<(), RelevanceError> {
    if got == expected {
        Ok(())
    } else {
        Err(RelevanceError::DimMismatch {
            what: what.to_string(),
            got,
            expected,
        })
    }
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `rᵢ` for every prompt `i`, given one (normalized) mask feature.
///
/// `softmax(10·[a, b])₀ = 1 / (1 + exp(10·(b − a)))`, the numerically stable form of the
/// paper's `exp(a)/(exp(a)+exp(b))` with LERF's temperature.
pub fn relevance_scores(
    feature: &[f32],
    text: &DictionaryEmbeddings,
) -> Result<Vec<f32>, RelevanceError> {
    let dim = text.validate()?;
    check_dim("mask feature", feature.len(), dim)?;
    let canon: Vec<f32> = text.canonical.iter().map(|c| dot(feature, c)).collect();
    let scores = text
        .prompts
        .iter()
        .map(|p| {
            let a = dot(feature, p);
            canon
                .iter()
                .map(|&b| 1.0 / (1.0 + (LERF_TEMPERATURE * (b - a)).exp()))
                .fold(f32::INFINITY, f32::min)
        })
        .collect();
    Ok(scores)
}

/// Picks the object for one mask: `argmax rᵢ` when `max rᵢ > τ`, else `None` (background).
/// Ties go to the lowest prompt index (the first maximum wins).
pub fn pick_object(scores: &[f32], tau: f32) -> Option<u8> {
    let mut best: Option<(usize, f32)> = None;
    for (i, &s) in scores.iter().enumerate() {
        if best.is_none_or(|(_, b)| s > b) {
            best = Some((i, s));
        }
    }
    // `i < MAX_DICTIONARY` (validated), so the cast is lossless.
    best.filter(|&(_, s)| s > tau).map(|(i, _)| i as u8)
}

/// Object ID per mask (`None` = background), from each mask's normalized CLIP feature.
pub fn object_ids(
    mask_features: &[Vec<f32>],
    text: &DictionaryEmbeddings,
    tau: f32,
) -> Result<Vec<Option<u8>>, RelevanceError> {
    text.validate()?;
    mask_features
        .iter()
        .map(|f| relevance_scores(f, text).map(|s| pick_object(&s, tau)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(v: &[f32]) -> Vec<f32> {
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        v.iter().map(|x| x / n).collect()
    }

    fn dict() -> DictionaryEmbeddings {
        DictionaryEmbeddings {
            prompts: vec![unit(&[1.0, 0.0, 0.0]), unit(&[0.0, 1.0, 0.0])],
            canonical: vec![unit(&[0.0, 0.0, 1.0]), unit(&[0.2, 0.2, 1.0])],
        }
    }

    #[test]
    fn scores_match_the_paper_formula_with_temperature() {
        let f = unit(&[0.9, 0.1, 0.3]);
        let d = dict();
        let s = relevance_scores(&f, &d).unwrap();
        for (i, p) in d.prompts.iter().enumerate() {
            let a = (LERF_TEMPERATURE * dot(&f, p)).exp();
            let expected = d
                .canonical
                .iter()
                .map(|c| a / (a + (LERF_TEMPERATURE * dot(&f, c)).exp()))
                .fold(f32::INFINITY, f32::min);
            assert!((s[i] - expected).abs() < 1e-6, "{} vs {}", s[i], expected);
        }
        assert!(s[0] > 0.5 && s[1] < 0.5);
    }

    #[test]
    fn ids_pick_best_prompt_or_background() {
        let d = dict();
        let feats = vec![
            unit(&[1.0, 0.1, 0.0]),
            unit(&[0.1, 1.0, 0.0]),
            unit(&[0.0, 0.0, 1.0]),
        ];
        let ids = object_ids(&feats, &d, DEFAULT_TAU).unwrap();
        assert_eq!(ids, vec![Some(0), Some(1), None]);
    }

    #[test]
    fn everything_below_tau_is_background() {
        let d = dict();
        let feats = vec![unit(&[1.0, 0.1, 0.0])];
        assert_eq!(object_ids(&feats, &d, 0.999_999).unwrap(), vec![None]);
    }

    #[test]
    fn ties_go_to_lowest_index() {
        assert_eq!(pick_object(&[0.7, 0.9, 0.9, 0.2], 0.5), Some(1));
        let d = DictionaryEmbeddings {
            prompts: vec![unit(&[1.0, 0.0]), unit(&[1.0, 0.0])],
            canonical: vec![unit(&[0.0, 1.0])],
        };
        assert_eq!(
            object_ids(&[unit(&[1.0, 0.0])], &d, 0.5).unwrap(),
            vec![Some(0)]
        );
    }

    #[test]
    fn threshold_is_strict() {
        assert_eq!(pick_object(&[0.5], 0.5), None);
        assert_eq!(pick_object(&[], 0.5), None);
    }

    #[test]
    fn empty_dictionary_is_a_clear_error() {
        let d = DictionaryEmbeddings {
            prompts: vec![],
            canonical: vec![vec![1.0]],
        };
        let err = object_ids(&[vec![1.0]], &d, 0.5).unwrap_err();
        assert!(matches!(err, RelevanceError::EmptyDictionary));
        assert!(err.to_string().contains("dictionary is empty"));
    }

    #[test]
    fn shape_errors_are_reported() {
        let d = dict();
        assert!(matches!(
            object_ids(&[vec![1.0, 0.0]], &d, 0.5),
            Err(RelevanceError::DimMismatch {
                got: 2,
                expected: 3,
                ..
            })
        ));
        let no_canon = DictionaryEmbeddings {
            prompts: d.prompts.clone(),
            canonical: vec![],
        };
        assert!(matches!(
            object_ids(&[], &no_canon, 0.5),
            Err(RelevanceError::NoCanonical)
        ));
        let big = DictionaryEmbeddings {
            prompts: vec![vec![1.0]; 256],
            canonical: vec![vec![1.0]],
        };
        assert!(matches!(
            big.validate(),
            Err(RelevanceError::TooManyPrompts(256))
        ));
    }
}
