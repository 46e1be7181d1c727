//! Checks of a PyTorch checkpoint (`.pt`, `.pth`, `.bin`: a zip of `*/data.pkl`, a pickle of
//! the state dict, and `*/data/N`, raw storages) made before candle's pickle reader sees it,
//! because that reader trusts the file (found by tests/fuzz_inputs.rs, docs/robustness.md):
//! a string length in the pickle is allocated before it is read (a flipped byte asks for
//! gigabytes), a memo entry can be pushed again and again (each copy doubles the size), a
//! tensor shape is allocated before its storage is read, and some malformed argument tuples
//! panic (`Vec::remove` out of bounds). Here the pickle is walked as a stack machine that only
//! tracks each object's nesting depth and size, the tensors' byte counts are compared with
//! their storage entries, and a panic of candle's reader becomes an error.

use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

/// A state dict's pickle is small (MobileSAM: 60 kB; SAM ViT-H: 200 kB): far above these
/// and it is not one.
const MAX_PICKLE_BYTES: u64 = 64 << 20;
/// Objects (and 16-byte units of strings) the unpickled state dict may hold.
const MAX_PICKLE_WEIGHT: u64 = 1 << 24;
/// Nesting depth of the unpickled objects (dropping them recurses).
const MAX_PICKLE_DEPTH: u32 = 1000;

/// Refuses a checkpoint that candle's reader would mishandle; the message does not name
/// the file (the caller's error does).
pub(crate) fn check(path: &Path) -> Result<(), String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
        .map_err(|e| format!("not a PyTorch zip checkpoint: {e}"))?;
    let mut sizes = HashMap::new();
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| format!("zip entry {i}: {e}"))?;
        let name = entry.name().to_owned();
        sizes.insert(name.clone(), entry.size());
        if name.ends_with("data.pkl") {
            let mut pickle = Vec::new();
            (&mut entry)
                .take(MAX_PICKLE_BYTES + 1)
                .read_to_end(&mut pickle)
                .map_err(|e| format!("{name}: {e}"))?;
            if pickle.len() as u64 > MAX_PICKLE_BYTES {
                return Err(format!("{name} is over {MAX_PICKLE_BYTES} bytes"));
            }
            scan_pickle(&pickle).map_err(|e| format!("{name}: {e}"))?;
        }
    }
    let infos =
        std::panic::catch_unwind(|| candle_core::pickle::read_pth_tensor_info(path, false, None))
            .map_err(|_| "malformed state dict (candle's pickle reader panicked)".to_string())?
            .map_err(|e| e.to_string())?;
    for t in infos {
        let bytes = (t.layout.shape().dims().iter())
            .try_fold(t.dtype.size_in_bytes(), |n, &d| n.checked_mul(d))
            .and_then(|n| n.checked_add(t.layout.start_offset()));
        let held = sizes.get(&t.path).copied().unwrap_or(0);
        if bytes.is_none_or(|b| b as u64 > held) {
            return Err(format!(
                "tensor `{}` {:?} {:?} needs more bytes than its storage `{}` holds ({held})",
                t.name,
                t.dtype,
                t.layout.shape(),
                t.path
            ));
        }
    }
    Ok(())
}

/// What the scan keeps of a stack entry.
#[derive(Clone, Copy)]
enum Slot {
    Mark,
    /// Nesting depth and weight (objects + string bytes / 16) of an object.
    Obj(u32, u64),
}

const ATOM: Slot = Slot::Obj(1, 1);

/// Walks the opcodes candle's reader knows, as it would, checking that every length fits
/// in the rest of the pickle and that no object grows too large or too deep. Stops quietly
/// where candle's reader would fail on its own (an unknown opcode, a stack underflow).
fn scan_pickle(p: &[u8]) -> Result<(), String> {
    let mut stack: Vec<Slot> = Vec::new();
    let mut memo: HashMap<u32, Slot> = HashMap::new();
    let mut i = 0usize;
    let take = |i: &mut usize, n: usize| -> Result<usize, String> {
        let at = *i;
        match at.checked_add(n).filter(|&end| end <= p.len()) {
            Some(end) => {
                *i = end;
                Ok(at)
            }
            None => Err(format!("opcode argument at byte {at} runs past the end")),
        }
    };
    let u32_at = |at: usize| u32::from_le_bytes([p[at], p[at + 1], p[at + 2], p[at + 3]]);
    while i < p.len() {
        let op = p[i];
        i += 1;
        let push_combined = |stack: &mut Vec<Slot>, parts: &[Slot]| -> Result<(), String> {
            let (mut depth, mut weight) = (0u32, 1u64);
            for s in parts {
                if let Slot::Obj(d, w) = s {
                    depth = depth.max(*d);
                    weight = weight.saturating_add(*w);
                }
            }
            if depth + 1 > MAX_PICKLE_DEPTH || weight > MAX_PICKLE_WEIGHT {
                return Err(format!(
                    "objects nested deeper than {MAX_PICKLE_DEPTH} or larger than {MAX_PICKLE_WEIGHT} units"
                ));
            }
            stack.push(Slot::Obj(depth + 1, weight));
            Ok(())
        };
        let pop_to_mark = |stack: &mut Vec<Slot>| -> Option<Vec<Slot>> {
            let m = stack.iter().rposition(|s| matches!(s, Slot::Mark))?;
            let items = stack.split_off(m + 1);
            stack.pop();
            Some(items)
        };
        match op {
            // PROTO, BININT1, BINPUT, BINGET: one byte.
            0x80 => {
                take(&mut i, 1)?;
            }
            b'K' => {
                take(&mut i, 1)?;
                stack.push(ATOM);
            }
            b'M' => {
                take(&mut i, 2)?;
                stack.push(ATOM);
            }
            b'J' => {
                take(&mut i, 4)?;
                stack.push(ATOM);
            }
            b'G' => {
                take(&mut i, 8)?;
                stack.push(ATOM);
            }
            b'X' => {
                let at = take(&mut i, 4)?;
                let len = u32_at(at) as usize;
                take(&mut i, len)?;
                stack.push(Slot::Obj(1, 1 + len as u64 / 16));
            }
            0x8a => {
                let at = take(&mut i, 1)?;
                take(&mut i, usize::from(p[at]))?;
                stack.push(ATOM);
            }
            b'c' => {
                for _ in 0..2 {
                    let nl = p[i..]
                        .iter()
                        .position(|&b| b == b'\n')
                        .ok_or("GLOBAL without its newline")?;
                    i += nl + 1;
                }
                stack.push(ATOM);
            }
            b'q' | b'r' => {
                let at = take(&mut i, if op == b'q' { 1 } else { 4 })?;
                let key = if op == b'q' {
                    u32::from(p[at])
                } else {
                    u32_at(at)
                };
                let Some(&top) = stack.last() else {
                    return Ok(());
                };
                memo.insert(key, top);
            }
            b'h' | b'j' => {
                let at = take(&mut i, if op == b'h' { 1 } else { 4 })?;
                let key = if op == b'h' {
                    u32::from(p[at])
                } else {
                    u32_at(at)
                };
                let Some(&v) = memo.get(&key) else {
                    return Ok(());
                };
                // A memo read copies the object: this is where a pickle can double its
                // size with every few bytes.
                let total: u64 = stack
                    .iter()
                    .map(|s| match s {
                        Slot::Obj(_, w) => *w,
                        Slot::Mark => 0,
                    })
                    .fold(0, u64::saturating_add);
                if let Slot::Obj(_, w) = v {
                    if total.saturating_add(w) > MAX_PICKLE_WEIGHT {
                        return Err(format!(
                            "memo copies grow the objects past {MAX_PICKLE_WEIGHT} units"
                        ));
                    }
                }
                stack.push(v);
            }
            b')' | b'}' | b'd' | b']' | b'N' | 0x88 | 0x89 => stack.push(ATOM),
            b'(' => stack.push(Slot::Mark),
            b't' => {
                let Some(items) = pop_to_mark(&mut stack) else {
                    return Ok(());
                };
                push_combined(&mut stack, &items)?;
            }
            0x85..=0x87 | b'Q' | b'R' | b'b' | 0x81 => {
                let n = match op {
                    0x85 | b'Q' => 1,
                    0x86 | b'R' | b'b' | 0x81 => 2,
                    _ => 3,
                };
                if stack.len() < n {
                    return Ok(());
                }
                let items = stack.split_off(stack.len() - n);
                push_combined(&mut stack, &items)?;
            }
            b'a' | b's' | b'e' | b'u' => {
                let items = match op {
                    b'a' | b's' => {
                        let n = if op == b'a' { 1 } else { 2 };
                        if stack.len() < n + 1 {
                            return Ok(());
                        }
                        stack.split_off(stack.len() - n)
                    }
                    _ => match pop_to_mark(&mut stack) {
                        Some(items) => items,
                        None => return Ok(()),
                    },
                };
                let Some(target) = stack.pop() else {
                    return Ok(());
                };
                let mut parts = items;
                parts.push(target);
                push_combined(&mut stack, &parts)?;
            }
            b'.' => return Ok(()),
            // Unknown to candle: its reader reports it.
            _ => return Ok(()),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lying_string_length_is_refused() {
        let mut p = vec![0x80, 2, b'X'];
        p.extend(u32::MAX.to_le_bytes());
        p.extend(b"abc.");
        assert!(scan_pickle(&p).unwrap_err().contains("past the end"));
        let mut ok = vec![0x80, 2, b'X'];
        ok.extend(3u32.to_le_bytes());
        ok.extend(b"abc.");
        scan_pickle(&ok).unwrap();
    }

    #[test]
    fn memo_doubling_is_refused() {
        // None, then 40 × (put 0, get 0, get 0, TUPLE2): 2^40 objects once unpickled.
        let mut p = vec![0x80, 2, b'N'];
        for _ in 0..40 {
            p.extend([b'q', 0, b'h', 0, b'h', 0, 0x86]);
        }
        p.push(b'.');
        assert!(scan_pickle(&p).is_err());
    }

    #[test]
    fn deep_nesting_is_refused() {
        let mut p = vec![0x80, 2, b'N'];
        p.extend(std::iter::repeat_n(0x85, 5000));
        p.push(b'.');
        assert!(scan_pickle(&p).unwrap_err().contains("deeper"));
    }
}
