//! Pretrained weights as a first-class step: what exists ([`catalog`]), fetching
//! and verifying it ([`fetch`]), and [`ensure`], which the commands that use weights call on
//! first use unless `--offline` (or `SEMDYNREG_OFFLINE=1`) is given.
//!
//! The folder is `$SEMDYNREG_WEIGHTS`, else `./weights`: the same rule as the loaders
//! (`metrics::lpips::weights_dir`, `semantics::sam::weights_dir`).

pub mod catalog;
pub mod fetch;

use catalog::Weight;
use std::path::PathBuf;

/// The weights folder the loaders read.
pub fn dir() -> PathBuf {
    metrics::lpips::weights_dir()
}

/// Whether `SEMDYNREG_OFFLINE` asks every command not to fetch (`1`, `true`, `yes`).
pub fn offline_env() -> bool {
    std::env::var("SEMDYNREG_OFFLINE")
        .is_ok_and(|v| matches!(v.to_ascii_lowercase().as_str(), "1" | "true" | "yes"))
}

pub(crate) fn spinner(msg: String) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(msg);
    pb.enable_steady_tick(std::time::Duration::from_millis(120));
    pb
}

/// Makes the weights `needed` present in [`dir`] for `command`: fetches the missing ones
/// unless `offline`, saying in one line what it fetched and where. A failed fetch is not an
/// error here: the command runs without them (its loader then says what is missing), and
/// the line says how to retry.
pub fn ensure(command: &str, needed: &[&Weight], offline: bool) {
    let dir = dir();
    let missing: Vec<&Weight> = needed
        .iter()
        .copied()
        .filter(|w| !dir.join(w.file).is_file())
        .collect();
    if missing.is_empty() {
        return;
    }
    let names: Vec<&str> = missing.iter().map(|w| w.file).collect();
    if offline || offline_env() {
        println!(
            "weights: {} not in {} and --offline given: {command} runs without (fetch: semdynreg weights fetch)",
            names.join(", "),
            dir.display()
        );
        return;
    }
    let mut lines = Vec::new();
    match fetch::fetch(&missing, &dir, |l| lines.push(l)) {
        Ok(()) => println!("weights: {} (first use, for {command})", lines.join("; ")),
        Err(e) => println!(
            "weights: could not fetch {} into {}: {e:#}\n  {command} runs without; retry with `semdynreg weights fetch`, or pass --offline",
            names.join(", "),
            dir.display()
        ),
    }
}
