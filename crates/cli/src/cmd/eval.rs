//! `semdynreg eval RUN [--split test]`: PSNR and SSIM of the latest checkpoint on a split,
//! written atomically to `RUN/eval/metrics.json` (`{"mean": {...}, "frames": [...]}`).

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub run: PathBuf,
    #[arg(long, default_value = "test")]
    pub split: String,
}

pub fn run(a: Args) -> Result<()> {
    let mut loaded = super::render::LoadedRun::open(&a.run)?;
    let frames = loaded.split(&a.split)?.to_vec();
    let report = loaded.evaluate(&frames)?;
    let out = a.run.join("eval").join("metrics.json");
    std::fs::create_dir_all(a.run.join("eval")).context("creating eval folder")?;
    scene::io::write_json(&out, &report).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: PSNR {:.3} SSIM {:.4} over {} frames → {}",
        a.split,
        report.mean.psnr,
        report.mean.ssim,
        report.frames.len(),
        out.display()
    );
    Ok(())
}
