//! Generates a toycars scene without the CLI's heavy dependencies, timing it:
//! `cargo run --release -p scene --example toycars -- OUT [scene1|scene2] [W H FRAMES SEED]`.
//! The product path is `semdynreg synth toycars`; this is for quick previews and timing
//! (it also times loading the scene back with `load_dataset`).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = args
        .first()
        .ok_or("usage: toycars OUT [scene1|scene2] [W H FRAMES SEED]")?;
    let mut cfg = scene::toycars::ToycarsConfig::default();
    if let Some(p) = args.get(1) {
        cfg.preset = p.parse()?;
    }
    let num = |i: usize, d: u64| -> Result<u64, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    cfg.width = num(2, 480)? as u32;
    cfg.height = num(3, 360)? as u32;
    cfg.frames = num(4, 120)? as usize;
    cfg.seed = num(5, 0)?;
    let start = std::time::Instant::now();
    scene::toycars::generate(&cfg, std::path::Path::new(out), &|_, _| {})?;
    let generated = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let ds = scene::load_dataset(std::path::Path::new(out), &scene::LoadOptions::default())?;
    println!(
        "{:?} {}x{} x{} frames: generate {generated:.2} s, load back {:.2} s ({} frames)",
        cfg.preset,
        cfg.width,
        cfg.height,
        cfg.frames,
        start.elapsed().as_secs_f64(),
        ds.all_frames().count()
    );
    Ok(())
}
