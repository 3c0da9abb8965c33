//! `prismap report` on a tiny plan: every row and column is there, plots are written,
//! and the reference is cached and reused.

use std::path::PathBuf;

use prismap::report::{BINS, PACKED_BINS, Plan, Report};

#[test]
fn tiny_report_has_every_row_column_and_plot() {
    let out = std::env::temp_dir().join(format!("prismap-report-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let report = Report {
        exe: PathBuf::from(env!("CARGO_BIN_EXE_prismap")),
        out: out.clone(),
        scenes: vec!["cornell-box".into()],
        plan: Plan {
            size: 16,
            photons: 2_000,
            final_gather_rays: 1,
            passes: 2,
            seconds: 0.2,
            reference_passes: 4,
            reference_photons: 2_000,
            reference_bins: 100,
            budget_bytes: 100_000,
        },
        quick: true,
    };
    let runs = report.run().unwrap();
    // 7 bins × 2 storages + rgb + packed and spiked at 2 bin counts, in two modes, plus 6
    // budget runs (full, compact, spiked; progressive and one pass).
    assert_eq!(
        runs.len(),
        2 * (2 * BINS.len() + 1 + 2 * PACKED_BINS.len()) + 6
    );
    let csv = std::fs::read_to_string(out.join("runs.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    for col in [
        "scene",
        "bins",
        "storage",
        "mode",
        "passes",
        "photons",
        "seconds",
        "psnr_db",
        "de2000_mean",
        "de2000_p95",
        "photon_map_bytes",
        "peak_rss_bytes",
        "spike_records",
    ] {
        assert!(header.contains(&col), "runs.csv lacks {col}");
    }
    assert_eq!(csv.lines().count(), runs.len() + 1);
    for r in &runs {
        assert!(r.psnr_db > 5.0, "{r:?}");
        assert!(r.peak_rss_bytes > 0 && r.photon_map_bytes > 0);
    }
    // Compact bytes per photon are flat across bins; full grows.
    let bpp = |storage: &str, bins: usize| {
        runs.iter()
            .find(|r| r.mode == "equal-photons" && r.storage == storage && r.bins == bins)
            .unwrap()
            .bytes_per_photon
    };
    assert_eq!(bpp("compact", 4), bpp("compact", 100));
    assert!(bpp("full", 100) > 10.0 * bpp("full", 4));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for b in BINS {
        assert!(
            md.contains(&format!("\n| {b} | ")),
            "report.md lacks the {b}-bin row"
        );
    }
    assert!(md.contains("\n| RGB | "));
    // Issue #14: packed records beside compact, with their 19 bytes a photon.
    assert!(
        md.contains("Packed (19 bytes a photon) and spiked (37) records"),
        "no packed table"
    );
    assert_eq!(bpp("packed", 20), 19.0);
    assert_eq!(bpp("spiked", 100), 37.0);
    // Every record against full at the same seed, with both colour models: a figure in
    // each cell (no "-": the Smits pair was rendered).
    let table = md
        .split("the compression alone")
        .nth(1)
        .expect("records-against-full table");
    let row20 = table.lines().find(|l| l.starts_with("| 20 | ")).unwrap();
    assert!(
        !row20.contains("| - |") && !row20.contains("- /"),
        "{row20}"
    );
    // At equal memory, spiked against compact is stated.
    assert!(
        md.contains("more compact photons than spiked ones"),
        "no equal-memory line"
    );
    for f in ["convergence-cornell-box.png", "memory-cornell-box.png"] {
        let img = image::open(out.join(f)).unwrap();
        assert_eq!((img.width(), img.height()), (900, 560), "{f}");
    }
    // Reference, full 8, compact 8, RGB side by side over their difference maps.
    let img = image::open(out.join("images-cornell-box.png")).unwrap();
    assert_eq!((img.width(), img.height()), (4 * (16 + 4), 2 * (16 + 4)));
    // A second run reuses the cached reference.
    let modified = std::fs::metadata(out.join("reference-cornell-box.exr"))
        .unwrap()
        .modified()
        .unwrap();
    report.run().unwrap();
    assert_eq!(
        std::fs::metadata(out.join("reference-cornell-box.exr"))
            .unwrap()
            .modified()
            .unwrap(),
        modified
    );
    std::fs::remove_dir_all(&out).unwrap();
}
