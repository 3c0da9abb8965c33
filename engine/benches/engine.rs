//! Micro-benchmarks of the engine's hot loops: `cargo bench --bench engine`.
//! Figures are recorded in BENCHMARKS.md.

/// The product's allocator (glibc's would add page faults the product does not have).
#[path = "../../src/allocator.rs"]
mod allocator;

use std::sync::atomic::AtomicBool;

use divan::{Bencher, black_box, counter::ItemsCount};
use glam::Vec3;
use prismap_engine::photon::record::oct_decode;
use prismap_engine::photon::{
    IrradianceCache, Kernel, PhotonMap, PhotonSettings, Reading, Storage, trace_photons,
};
use prismap_engine::render::RenderSettings;
use prismap_engine::render::session::{PRECOMPUTE_EVERY, next_radius_sq_factor};
use prismap_engine::sampling::{Purpose, Rng, uniform_sphere};
use prismap_engine::scene::{SpectralScene, load_builtin};
use prismap_engine::spectral::{BinGrid, Role, Spectrum, spd};

fn main() {
    allocator::keep_freed_memory();
    divan::main();
}

fn cornell(bins: usize) -> SpectralScene {
    SpectralScene::new(
        &load_builtin("cornell-box").unwrap(),
        BinGrid::with_bins(bins).unwrap(),
    )
}

/// The photon pass's settings the benches trace with (no budget).
fn photon_settings(photons: usize, storage: Storage, caustic_factor: usize) -> PhotonSettings {
    PhotonSettings {
        caustic_factor,
        ..PhotonSettings::new(photons, storage.record())
    }
}

/// Every `step`-th photon of `map` (at most `count`) as a query: its position and its own
/// stored surface normal, as the gather's queries are.
fn photon_queries(map: &PhotonMap, step: usize, count: usize) -> Vec<(Vec3, Vec3)> {
    (0..map.len())
        .step_by(step.max(1))
        .take(count)
        .map(|i| {
            let n = oct_decode(map.normal_code(i));
            (Vec3::from_array(map.positions()[i]), n)
        })
        .collect()
}

/// Runs `kernel`'s density estimate at every point (one thread), the grid's bins wide.
fn bench_estimates(
    bencher: Bencher,
    grid: &BinGrid,
    map: &PhotonMap,
    kernel: Kernel,
    points: &[(Vec3, Vec3)],
) {
    let mut out = vec![0.0f32; grid.len()];
    let mut found = Vec::new();
    bencher
        .counter(ItemsCount::new(points.len()))
        .bench_local(|| {
            let mut radii = 0.0;
            for &(p, normal) in points {
                out.fill(0.0);
                radii += map
                    .estimate(grid, p, normal, kernel, &mut found, &mut out)
                    .r;
            }
            radii
        });
}

/// Emits and traces 50 000 photons of `scene` (all threads, compact storage) per iteration.
fn bench_tracing(bencher: Bencher, scene: &SpectralScene) {
    let settings = photon_settings(50_000, Storage::Compact, 1);
    let cancel = AtomicBool::new(false);
    bencher
        .counter(ItemsCount::new(settings.photons))
        .bench(|| {
            trace_photons(scene, &settings, 1, 1, &cancel)
                .unwrap()
                .global
                .len()
        });
}

/// Photons emitted and traced (all threads), Cornell box, compact storage.
#[divan::bench(args = [4, 20, 100], sample_count = 10)]
fn photons_traced(bencher: Bencher, bins: usize) {
    bench_tracing(bencher, &cornell(bins));
}

/// The cost of a texture in the photon pass: Blender's textured-glass fixture (an
/// image-textured cube, a glass sphere, a floor, under a Sun) traced with its texture and
/// with the texture removed (the factor alone), 20 bins compact.
#[divan::bench(args = [true, false], sample_count = 10)]
fn photons_traced_textured(bencher: Bencher, textured: bool) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/blender/textured-glass.glb");
    let mut scene = prismap_engine::scene::load(&path).unwrap();
    if !textured {
        for m in &mut scene.materials {
            m.base_color_texture = None;
        }
    }
    bench_tracing(
        bencher,
        &SpectralScene::new(&scene, BinGrid::with_bins(20).unwrap()),
    );
}

/// What the gather benches query.
struct GatherSetup {
    scene: SpectralScene,
    map: PhotonMap,
    /// 2 000 photons' positions and surface normals.
    points: Vec<(Vec3, Vec3)>,
    /// The median 48-nearest radius.
    r: f32,
    /// The renderer's kind of adaptive kernel: 48 nearest, from `r` out to twice it.
    kernel: Kernel,
}

/// A global map of the Cornell box (100 000 photons, 20 bins) and 2 000 of its photons'
/// positions and surface normals to query at.
fn gather_setup(storage: Storage) -> GatherSetup {
    let scene = cornell(20);
    let settings = photon_settings(100_000, storage, 1);
    let map = trace_photons(&scene, &settings, 1, 1, &AtomicBool::new(false))
        .unwrap()
        .global;
    let r = map.typical_knn_radius(48, 256).unwrap();
    let points = photon_queries(&map, 97, 2000);
    let kernel = Kernel {
        k: 48,
        r_max: 2.0 * r,
        r_start: r,
        shrink: 1.0,
    };
    GatherSetup {
        scene,
        map,
        points,
        r,
        kernel,
    }
}

/// Fixed-radius queries on the global map (one thread), full vs compact at 20 bins.
#[divan::bench(args = [Storage::Full, Storage::Compact], sample_count = 10)]
fn gather_queries(bencher: Bencher, storage: Storage) {
    let GatherSetup {
        scene,
        map,
        points,
        r,
        ..
    } = gather_setup(storage);
    let mut out = vec![0.0f32; 20];
    bencher
        .counter(ItemsCount::new(points.len()))
        .bench_local(|| {
            let mut n = 0;
            for &(p, normal) in &points {
                out.fill(0.0);
                n += map.gather(&scene.grid, p, normal, r, &mut out);
            }
            n
        });
}

/// The renderer's own estimate (one thread): the 48 nearest photons on the query's
/// surface, searched from the typical radius out to twice it, full vs compact at 20 bins.
#[divan::bench(args = [Storage::Full, Storage::Compact], sample_count = 10)]
fn gather_knn_estimates(bencher: Bencher, storage: Storage) {
    let GatherSetup {
        scene,
        map,
        points,
        kernel,
        ..
    } = gather_setup(storage);
    bench_estimates(bencher, &scene.grid, &map, kernel, &points);
}

/// What a final-gather ray reads (one thread): the irradiance precomputed at every
/// `PRECOMPUTE_EVERY`-th photon, looked up at the nearest point on the query's surface,
/// full vs compact at 20 bins. Built with the renderer's own kernel (48 nearest, out to
/// twice the typical radius).
#[divan::bench(args = [Storage::Full, Storage::Compact], sample_count = 10)]
fn irradiance_lookups(bencher: Bencher, storage: Storage) {
    let GatherSetup {
        scene,
        map,
        points,
        kernel,
        ..
    } = gather_setup(storage);
    let r_min = 1e-6 * scene.diagonal(); // as the renderer's
    let cache = IrradianceCache::build(
        &map,
        &scene.grid,
        Some(&scene),
        kernel,
        PRECOMPUTE_EVERY,
        r_min,
        kernel.r_max,
        &AtomicBool::new(false),
    )
    .unwrap();
    let mut out = vec![0.0f32; 20];
    bencher
        .counter(ItemsCount::new(points.len()))
        .bench_local(|| {
            let mut hits = 0;
            for &(p, normal) in &points {
                hits +=
                    usize::from(cache.lookup(&scene.grid, p, normal, &mut out) == Reading::Value);
            }
            hits
        });
}

/// The caustic map's estimates (one thread), as the gather runs them on the prism at its
/// defaults: 100 bins compact, 25 000 photons a pass traced 4 times over for the caustic
/// map, the 96 nearest (24 × the caustic factor) searched from 1.2 typical radii out to
/// the same cap. Queried at 2 000 caustic photons on their own surfaces, i.e. only where
/// the search runs (on the prism most camera hits end at the occupancy test instead).
/// At pass 1 (no shrink) and pass 32 (the radius shrunk by the default Knaus–Zwicker α, the
/// search folded as the renderer folds it: `Kernel::adaptive`).
#[divan::bench(args = [1, 32], sample_count = 10)]
fn caustic_estimates(bencher: Bencher, pass: u64) {
    let scene = SpectralScene::new(
        &load_builtin("prism").unwrap(),
        BinGrid::with_bins(100).unwrap(),
    );
    let settings = photon_settings(25_000, Storage::Compact, 4);
    let map = trace_photons(&scene, &settings, 1, 1, &AtomicBool::new(false))
        .unwrap()
        .caustic
        .expect("the prism has a caustic map");
    let k = 96;
    let r = map.typical_knn_radius(k, 256).unwrap();
    let alpha = RenderSettings::default().alpha;
    let factor = (1..pass).fold(1.0, |f, p| next_radius_sq_factor(f, p, alpha));
    let kernel = Kernel::adaptive(k, 1.2 * r, 1.2 * r, factor.sqrt() as f32);
    let points = photon_queries(&map, map.len() / 2000, 2000);
    bench_estimates(bencher, &scene.grid, &map, kernel, &points);
}

/// Closest-hit rays through the CWBVH (one thread), incoherent directions from the box centre.
#[divan::bench(sample_count = 10)]
fn bvh_rays(bencher: Bencher) {
    let scene = cornell(4);
    let mut rng = Rng::stream(1, 0, 0, Purpose::Photon);
    let rays: Vec<(Vec3, Vec3)> = (0..10_000)
        .map(|_| {
            let o = Vec3::new(278.0, 274.0, 279.0)
                + 200.0 * (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5);
            (o, uniform_sphere(rng.next_2d()))
        })
        .collect();
    bencher
        .counter(ItemsCount::new(rays.len()))
        .bench_local(|| {
            rays.iter()
                .filter(|(o, d)| scene.accel.intersect(*o, *d, f32::INFINITY).is_some())
                .count()
        });
}

fn fluxes(n: usize) -> (BinGrid, Vec<Vec<f32>>) {
    let g = BinGrid::with_bins(n).unwrap();
    let light = g.project(&Spectrum::illuminant([17.0, 12.0, 4.0]), Role::Emission);
    let fluxes = [[0.73, 0.73, 0.73], [0.63, 0.065, 0.05], [0.14, 0.45, 0.091]]
        .iter()
        .map(|rgb| {
            let mut f = light.clone();
            spd::mul_assign(
                &mut f,
                &g.project(&Spectrum::reflectance(*rgb), Role::Reflectance),
            );
            f
        })
        .collect();
    (g, fluxes)
}

/// Compaction of one smooth flux into its Smits triplet (ns per photon).
#[divan::bench(args = [4, 5, 6, 8, 10, 20, 100])]
fn compact_encode(bencher: Bencher, n: usize) {
    let (g, fluxes) = fluxes(n);
    let smits = g.smits().unwrap();
    bencher
        .counter(ItemsCount::new(fluxes.len()))
        .bench_local(|| {
            fluxes
                .iter()
                .map(|f| smits.encode(black_box(f))[0])
                .sum::<f32>()
        });
}

/// Expansion of one triplet to N bins (ns per photon, the per-photon cost without branch sums).
#[divan::bench(args = [4, 5, 6, 8, 10, 20, 100])]
fn compact_decode(bencher: Bencher, n: usize) {
    let (g, fluxes) = fluxes(n);
    let smits = g.smits().unwrap();
    let triplets: Vec<[f32; 3]> = fluxes.iter().map(|f| smits.encode(f)).collect();
    let mut out = vec![0.0f32; n];
    bencher
        .counter(ItemsCount::new(triplets.len()))
        .bench_local(|| {
            for t in &triplets {
                smits.decode_into(black_box(*t), &mut out);
            }
            out[0]
        });
}

/// The kd order of the Cornell box's global-map photon positions from four passes of
/// 50 000 emitted photons (about 325 000 stored), on all threads: the build every photon
/// pass ends with.
#[divan::bench(sample_count = 20)]
fn kd_build(bencher: Bencher) {
    let scene = cornell(4);
    let settings = photon_settings(50_000, Storage::Compact, 1);
    let cancel = AtomicBool::new(false);
    let positions: Vec<[f32; 3]> = (1..=4)
        .flat_map(|pass| {
            let maps = trace_photons(&scene, &settings, 1, pass, &cancel).unwrap();
            maps.global.positions().to_vec()
        })
        .collect();
    bencher.counter(ItemsCount::new(positions.len())).bench(|| {
        prismap_engine::photon::kdtree::build_order(black_box(&positions))
            .1
            .len()
    });
}

/// A 512² image to 8-bit sRGB (exposure, clamp, the transfer curve): what the viewer's UI
/// thread does with each new image, and every PNG. Pixels spread over the whole curve
/// (cubes of uniform numbers, times 2, so that some clip).
#[divan::bench(sample_count = 20)]
fn display_encode(bencher: Bencher) {
    let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
    let pixels: Vec<[f32; 3]> = (0..512 * 512)
        .map(|_| [(); 3].map(|()| 2.0 * rng.next_f32().powi(3)))
        .collect();
    let image = prismap_engine::render::Image {
        width: 512,
        height: 512,
        pixels,
    };
    bencher
        .counter(ItemsCount::new(image.pixels.len()))
        .bench_local(|| prismap_engine::output::to_srgb8(black_box(&image), 0.7));
}
