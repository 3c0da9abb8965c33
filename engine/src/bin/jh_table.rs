//! Writes the Jakob–Hanika coefficient table the renderer ships with
//! (`assets/data/jh_srgb.bin`): `cargo run --release -p prismap-engine --bin jh_table
//! [-- OUTPUT [RESOLUTION]]`. See `prismap_engine::spectral::jakob_hanika`.

use std::process::ExitCode;

use prismap_engine::spectral::jakob_hanika::{RES, Table};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .unwrap_or_else(|| "assets/data/jh_srgb.bin".to_string());
    let res = match args.next().map(|s| s.parse::<usize>()) {
        None => RES,
        Some(Ok(r)) if (2..=256).contains(&r) => r,
        Some(_) => {
            eprintln!("jh_table: RESOLUTION must be an integer in 2–256");
            return ExitCode::FAILURE;
        }
    };
    let start = std::time::Instant::now();
    let table = Table::fit(res);
    let bytes = table.to_bytes();
    if let Err(e) = std::fs::write(&out, &bytes) {
        eprintln!("jh_table: cannot write {out}: {e}");
        return ExitCode::FAILURE;
    }
    println!(
        "wrote {out}: {res}³ × 3 blocks, {} bytes, fitted in {:.1} s",
        bytes.len(),
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
