//! The CLIP byte-pair-encoding tokenizer, following `open_clip.tokenizer.SimpleTokenizer`
//! (itself OpenAI CLIP's `simple_tokenizer.py`) with its default `clean='lower'`.
//!
//! The merges file `bpe_simple_vocab_16e6.txt.gz` (1.3 MB, MIT, see `BPE_VOCAB_LICENSE.txt`)
//! is compiled into the binary, so no weights folder or Python is needed to tokenize.
//! Text cleaning reproduces `whitespace_clean(basic_clean(x)).lower()` except ftfy's
//! mojibake repair: we apply the parts of `ftfy.fix_text` that change ordinary prompts
//! (curly quotes → straight, NFC normalization) and `html.unescape` applied twice.

use std::collections::HashMap;
use std::io::Read;

use regex::Regex;
use unicode_normalization::UnicodeNormalization;

use super::ClipError;

const VOCAB_GZ: &[u8] = include_bytes!("bpe_simple_vocab_16e6.txt.gz");

/// Context length of every CLIP text tower (OpenAI and OpenCLIP).
pub const CONTEXT_LENGTH: usize = 77;
/// Number of merges CLIP keeps from the file: `49152 − 256 − 2` (SimpleTokenizer).
const N_MERGES: usize = 49152 - 256 - 2;
const SOT: &str = "<start_of_text>";
const EOT: &str = "<end_of_text>";

/// CLIP's BPE tokenizer: 49,408 ids, `<start_of_text>` = 49406, `<end_of_text>` = 49407.
pub struct Tokenizer {
    encoder: HashMap<String, u32>,
    ranks: HashMap<(String, String), usize>,
    byte_encoder: [char; 256],
    pattern: Regex,
    sot: u32,
    eot: u32,
}

/// GPT-2's reversible byte → printable-char table (`bytes_to_unicode`).
fn bytes_to_unicode() -> [char; 256] {
    let printable =
        |b: u32| (33..=126).contains(&b) || (161..=172).contains(&b) || (174..=255).contains(&b);
    let mut table = ['\0'; 256];
    let mut extra = 0u32;
    for b in 0..256u32 {
        let c = if printable(b) {
            b
        } else {
            extra += 1;
            255 + extra
        };
        table[b as usize] = char::from_u32(c).expect("code points below 512 are valid chars");
    }
    table
}

impl Tokenizer {
    /// Builds the tokenizer from the vendored merges file.
    pub fn new() -> Result<Self, ClipError> {
        let mut text = String::new();
        flate2::read::GzDecoder::new(VOCAB_GZ)
            .read_to_string(&mut text)
            .map_err(|e| {
                ClipError::Tokenizer(format!(
                    "cannot decompress the vendored BPE vocabulary: {e}"
                ))
            })?;
        Self::from_merges(&text)
    }

    /// Builds the tokenizer from the text of a `bpe_simple_vocab_16e6.txt` file.
    pub fn from_merges(text: &str) -> Result<Self, ClipError> {
        let merges: Vec<(String, String)> = text
            .split('\n')
            .skip(1)
            .take(N_MERGES)
            .map(|line| {
                let mut parts = line.split_whitespace();
                match (parts.next(), parts.next()) {
                    (Some(a), Some(b)) => Ok((a.to_string(), b.to_string())),
                    _ => Err(ClipError::Tokenizer(format!(
                        "malformed BPE merge line {line:?}"
                    ))),
                }
            })
            .collect::<Result<_, _>>()?;
        if merges.len() != N_MERGES {
            return Err(ClipError::Tokenizer(format!(
                "expected {N_MERGES} merges, found {}",
                merges.len()
            )));
        }
        let byte_encoder = bytes_to_unicode();
        // Vocabulary order is part of the format: byte symbols in `bytes_to_unicode`'s
        // insertion order (printable bytes, then the remapped ones, i.e. by code point),
        // the same + "</w>", merges, specials.
        let mut symbols: Vec<char> = byte_encoder.to_vec();
        symbols.sort_unstable();
        let mut vocab: Vec<String> = symbols.iter().map(|c| c.to_string()).collect();
        vocab.extend(symbols.iter().map(|c| format!("{c}</w>")));
        vocab.extend(merges.iter().map(|(a, b)| format!("{a}{b}")));
        vocab.push(SOT.to_string());
        vocab.push(EOT.to_string());
        let encoder: HashMap<String, u32> = vocab
            .into_iter()
            .enumerate()
            .map(|(i, t)| (t, i as u32))
            .collect();
        let ranks = merges
            .into_iter()
            .enumerate()
            .map(|(i, m)| (m, i))
            .collect();
        // SimpleTokenizer's pattern, verbatim (Rust's regex is leftmost-first like Python's).
        let pattern = Regex::new(&format!(
            r"(?i){SOT}|{EOT}|'s|'t|'re|'ve|'m|'ll|'d|[\p{{L}}]+|[\p{{N}}]|[^\s\p{{L}}\p{{N}}]+"
        ))
        .map_err(|e| ClipError::Tokenizer(e.to_string()))?;
        Ok(Self {
            sot: encoder[SOT],
            eot: encoder[EOT],
            encoder,
            ranks,
            byte_encoder,
            pattern,
        })
    }

    /// Id of `<start_of_text>`.
    pub fn sot(&self) -> u32 {
        self.sot
    }

    /// Id of `<end_of_text>` (the largest id: the text tower pools at the argmax id).
    pub fn eot(&self) -> u32 {
        self.eot
    }

    /// BPE ids of `text` after cleaning, without SOT/EOT (`SimpleTokenizer.encode`).
    pub fn encode(&self, text: &str) -> Vec<u32> {
        let cleaned = clean(text);
        let mut ids = Vec::new();
        for m in self.pattern.find_iter(&cleaned) {
            let token = m.as_str();
            if token == SOT || token == EOT {
                ids.push(self.encoder[token]);
                continue;
            }
            let mapped: String = token
                .bytes()
                .map(|b| self.byte_encoder[b as usize])
                .collect();
            ids.extend(
                self.bpe(&mapped)
                    .iter()
                    .map(|piece| self.encoder[piece.as_str()]),
            );
        }
        ids
    }

    /// `[SOT] + encode(text) + [EOT]`, zero-padded to `context`; over-long texts are cut and
    /// end in EOT, as `SimpleTokenizer.__call__`.
    pub fn tokenize(&self, text: &str, context: usize) -> Vec<u32> {
        let mut ids = Vec::with_capacity(context);
        ids.push(self.sot);
        ids.extend(self.encode(text));
        ids.push(self.eot);
        if ids.len() > context {
            ids.truncate(context);
            if let Some(last) = ids.last_mut() {
                *last = self.eot;
            }
        }
        ids.resize(context, 0);
        ids
    }

    /// Applies the merges to one pre-token (already byte-mapped), lowest rank first.
    fn bpe(&self, token: &str) -> Vec<String> {
        let mut word: Vec<String> = token.chars().map(String::from).collect();
        if let Some(last) = word.last_mut() {
            last.push_str("</w>");
        }
        while word.len() > 1 {
            let best = word
                .windows(2)
                .filter_map(|w| {
                    self.ranks
                        .get(&(w[0].clone(), w[1].clone()))
                        .map(|&r| (r, w[0].clone(), w[1].clone()))
                })
                .min();
            let Some((_, first, second)) = best else {
                break;
            };
            let mut merged = Vec::with_capacity(word.len());
            let mut i = 0;
            while i < word.len() {
                if i + 1 < word.len() && word[i] == first && word[i + 1] == second {
                    merged.push(format!("{first}{second}"));
                    i += 2;
                } else {
                    merged.push(std::mem::take(&mut word[i]));
                    i += 1;
                }
            }
            word = merged;
        }
        word
    }
}

/// `whitespace_clean(basic_clean(text)).lower()` (see the module note on ftfy).
pub fn clean(text: &str) -> String {
    let uncurled: String = text
        .chars()
        .map(|c| match c {
            '\u{2018}' | '\u{2019}' | '\u{201A}' | '\u{201B}' => '\'',
            '\u{201C}' | '\u{201D}' | '\u{201E}' | '\u{201F}' => '"',
            c => c,
        })
        .nfc()
        .collect();
    let unescaped = html_unescape(&html_unescape(&uncurled));
    unescaped
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_lowercase()
}

/// The HTML character references that occur in prompts: the five XML entities, `&nbsp;`
/// and numeric references (`&#39;`, `&#x27;`). Unknown entities are left as written.
fn html_unescape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find('&') {
        out.push_str(&rest[..start]);
        rest = &rest[start..];
        let decoded = rest.find(';').filter(|&end| end <= 10).and_then(|end| {
            let name = &rest[1..end];
            let c = match name {
                "amp" => Some('&'),
                "lt" => Some('<'),
                "gt" => Some('>'),
                "quot" => Some('"'),
                "apos" => Some('\''),
                "nbsp" => Some('\u{a0}'),
                _ => numeric_reference(name),
            };
            c.map(|c| (c, end + 1))
        });
        match decoded {
            Some((c, len)) => {
                out.push(c);
                rest = &rest[len..];
            }
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

fn numeric_reference(name: &str) -> Option<char> {
    let digits = name.strip_prefix('#')?;
    let code = match digits.strip_prefix(['x', 'X']) {
        Some(hex) => u32::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    char::from_u32(code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_ids_and_padding() {
        let tok = Tokenizer::new().unwrap();
        assert_eq!((tok.sot(), tok.eot()), (49406, 49407));
        let ids = tok.tokenize("a", 8);
        assert_eq!(ids.len(), 8);
        assert_eq!(ids[0], 49406);
        assert_eq!(ids[2], 49407);
        assert!(ids[3..].iter().all(|&i| i == 0));
    }

    #[test]
    fn truncation_ends_in_eot() {
        let tok = Tokenizer::new().unwrap();
        let ids = tok.tokenize(&"car ".repeat(100), CONTEXT_LENGTH);
        assert_eq!(ids.len(), CONTEXT_LENGTH);
        assert_eq!(ids[CONTEXT_LENGTH - 1], tok.eot());
    }

    #[test]
    fn cleaning() {
        assert_eq!(clean("  White\tSUV \n"), "white suv");
        assert_eq!(
            clean("driver\u{2019}s &amp;amp; &#39;car&#x27;"),
            "driver's & 'car'"
        );
        assert_eq!(clean("a & b &bogus; c"), "a & b &bogus; c");
    }

    #[test]
    fn malformed_merges_are_an_error() {
        assert!(Tokenizer::from_merges("header\ni n\n").is_err());
        assert!(Tokenizer::from_merges("header\nlonely\n").is_err());
    }
}
