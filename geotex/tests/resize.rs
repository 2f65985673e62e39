//! The whole chain on the synthetic models of `fresco_datasets::geometric_texture`, judged
//! against the generator's ground truth (issue 17's "must show"): segmentation agreement,
//! feature sizes after a 2x stretch with each method, and the bad inputs.

use fresco_core::NoProgress;
use fresco_core::nalgebra::Point3;
use fresco_datasets::geometric_texture as gt;
use fresco_geotex::curvature::{CurvatureConfig, principal_curvatures};
use fresco_geotex::segmentation::{SegmentationConfig, segment};
use fresco_geotex::{GeotexError, Method, ResizeConfig, Target, graph, resize};

fn config(method: Method) -> ResizeConfig {
    ResizeConfig {
        method,
        ..ResizeConfig::default()
    }
}

/// The thread's pitch measured on the output (z period of the displacement of region 1).
fn output_pitch(out: &fresco_geotex::Resized) -> f64 {
    let m = out.report.measurement.as_ref().expect("measured");
    m.output.regions[0].period[2].expect("the output has a period along z")
}

/// Seeds every seed-dependent test runs over: the segmentation's sample subset and the
/// synthesis' random start and template shifts change with the seed, and a property that
/// holds at one seed only is luck.
const SEEDS: std::ops::Range<u64> = 0..5;

#[test]
fn segmentation_agrees_with_the_ground_truth_on_nine_tenths_of_the_vertices_at_every_seed() {
    for model in gt::all_models() {
        let mesh = &model.mesh;
        let (_, g) = graph::prepare(mesh).unwrap();
        let normals = mesh.vertex_normals();
        let cc = CurvatureConfig::default();
        let curv = principal_curvatures(
            mesh,
            &normals,
            cc.radius_in_edges * g.mean_edge,
            cc.columns_per_radius,
        );
        for seed in SEEDS {
            let cfg = SegmentationConfig {
                seed,
                ..SegmentationConfig::default()
            };
            let seg = segment(mesh, &g, &curv, &cfg);
            let agree = seg
                .labels
                .iter()
                .zip(&model.labels)
                .filter(|(a, b)| (**a != 0) == (**b != 0))
                .count() as f64
                / mesh.positions.len() as f64;
            eprintln!("{} seed {seed}: agreement {agree:.4}", model.name);
            assert!(agree >= 0.9, "{} seed {seed}: {agree}", model.name);
            // One region per generator texture, each mostly its vertices: two kinds of
            // bumps are two sorts of texture, one scale pattern is one. (Four fifths: the
            // generator's labels stop where a texture's fade reaches one half, the
            // segmentation also takes some of the fade beyond; 89% on the cylinder.)
            assert_eq!(
                seg.regions.len(),
                model.textures.len(),
                "{} seed {seed}: {:?}",
                model.name,
                seg.regions
            );
            let mut seen = Vec::new();
            for region in 1..=seg.regions.len() as u32 {
                let mut counts = [0usize; 256];
                for (l, t) in seg.labels.iter().zip(&model.labels) {
                    if *l == region {
                        counts[*t as usize] += 1;
                    }
                }
                let total: usize = counts.iter().sum();
                let (truth, most) = (1..256)
                    .map(|t| (t, counts[t]))
                    .max_by_key(|x| x.1)
                    .unwrap();
                let purity = most as f64 / total as f64;
                assert!(
                    purity >= 0.8 && !seen.contains(&truth),
                    "{} seed {seed}: region {region} is {purity} label {truth} ({seen:?} seen)",
                    model.name
                );
                seen.push(truth);
            }
        }
    }
}

/// How the seed-dependent texture tests judge a ratio out/in that should be 1: the mean over
/// [`SEEDS`] within the 5% (the method is randomised: its result is the mean over
/// draws), and every seed within `PER_SEED` (no draw far off).
const PER_SEED: f64 = 0.12;

fn check_ratios(what: &str, ratios: &[f64]) {
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    eprintln!("{what}: ratios {ratios:.3?}, mean {mean:.3}");
    assert!(
        (mean - 1.0).abs() < 0.05,
        "{what}: mean {mean} of {ratios:?}"
    );
    for (seed, r) in SEEDS.zip(ratios) {
        assert!((r - 1.0).abs() < PER_SEED, "{what}: seed {seed} ratio {r}");
    }
}

/// The bound at every seed. Seeds 0-4 give pitch -1.6, -0.7, 0.0, -1.4, +0.6%;
/// bumps (small x/y, big x/y) 1.023/1.005 0.960/0.974, 0.974/1.007 1.000/0.982,
/// 0.990/1.017 0.991/1.012, 1.014/1.008 0.995/0.951, 0.981/0.996 1.004/1.025 (the output
/// measured over the input's faired base carried through the resize; session 12: the
/// texture method's grid keeps each region's relative size, `optimise_keeping_regions`;
/// before, the big bumps along y read 0.949, 0.970, 0.951, 0.931, 0.944).
fn check_ratios_strictly(what: &str, ratios: &[f64]) {
    for (seed, r) in SEEDS.zip(ratios) {
        assert!((r - 1.0).abs() < 0.05, "{what}: seed {seed} ratio {r}");
    }
}

/// Per seed, the texture method's pitch out/in: computed once for the mean and the strict
/// test (each resize of the five seeds costs seconds).
fn thread_pitch_ratios() -> &'static [f64] {
    static RATIOS: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    RATIOS.get_or_init(compute_thread_pitch_ratios)
}

fn compute_thread_pitch_ratios() -> Vec<f64> {
    let cfg = gt::ThreadedCylinderConfig::default();
    let model = gt::threaded_cylinder(&cfg);
    let truth = match model.textures[0].kind {
        gt::TextureKind::Thread { pitch, .. } => pitch,
        _ => unreachable!(),
    };
    let depth = match model.textures[0].kind {
        gt::TextureKind::Thread { depth, .. } => depth,
        _ => unreachable!(),
    };
    let target = Target::Scale([1.0, 1.0, 2.0]);
    let uniform = resize(&model.mesh, &target, &config(Method::Uniform), &NoProgress).unwrap();
    let pu = output_pitch(&uniform);
    eprintln!("pitch: truth {truth}, uniform {pu}");
    // The bound: about +100% with uniform.
    assert!(
        (pu / truth - 2.0).abs() < 0.05,
        "uniform pitch {pu} vs {truth}"
    );
    SEEDS
        .map(|seed| {
            let cfg = ResizeConfig {
                seed,
                ..config(Method::Texture)
            };
            let textured = resize(&model.mesh, &target, &cfg, &NoProgress).unwrap();
            // The result reaches the target box (the texture adds its crests to the base's
            // box).
            let size = textured.report.output_size;
            let input = textured.report.input_size;
            assert!(
                (size[2] / input[2] - 2.0).abs() < 0.02,
                "{size:?} {input:?}"
            );
            assert!(
                (size[0] / input[0] - 1.0).abs() < 0.02,
                "{size:?} {input:?}"
            );
            // Base-shape error: the faired output against the faired input resized by the
            // same deformation, within a tenth of the thread's depth (RMS).
            let err = textured.report.measurement.as_ref().unwrap().base_error;
            assert!(err.rms < 0.1 * depth, "seed {seed}: {err:?}");
            output_pitch(&textured) / truth
        })
        .collect()
}

#[test]
fn thread_pitch_is_kept_by_texture_and_doubled_by_uniform() {
    check_ratios("texture pitch", thread_pitch_ratios());
}

#[test]
fn thread_pitch_is_kept_within_five_percent_at_every_seed() {
    check_ratios_strictly("texture pitch", thread_pitch_ratios());
}

#[test]
fn a_uniform_stretch_reads_as_the_stretch_on_every_model() {
    // Uniform scaling stretches every feature exactly 2x along the stretch and keeps it
    // across. The measure reads the output over the input's faired base carried through
    // the same map (measure.rs): on the box's flat patches and the cylinder's thread it
    // maps the input's field onto the output's, and reads the stretch to round-off
    // (measured 1.999-2.000 and 1.000; 1% leaves room for the periodogram's frequency
    // step and the closest-point search). On the blob's curved cap a stretch also raises
    // the heights where it flattens the slope (by up to 1.6x on the cap's flanks along x),
    // which changes which plates pass the region's threshold: measured 1.958 / 1.007; the
    // issue's 5% bound, within which the measure must tell a kept size from a doubled
    // one. Before (the output faired again) the blob read 1.20 / 1.01.
    for model in gt::all_models() {
        let thread = model.name == "threaded-cylinder";
        let scale = if thread {
            [1.0, 1.0, 2.0]
        } else {
            [2.0, 1.0, 1.0]
        };
        let out = resize(
            &model.mesh,
            &Target::Scale(scale),
            &config(Method::Uniform),
            &NoProgress,
        )
        .unwrap();
        let m = out.report.measurement.as_ref().unwrap();
        assert_eq!(
            m.input.regions.len(),
            model.textures.len(),
            "{}",
            model.name
        );
        for (before, after) in m.input.regions.iter().zip(&m.output.regions) {
            let ratio = |a: usize, what: &str| -> f64 {
                let (i, o) = if what == "period" {
                    (before.period[a], after.period[a])
                } else {
                    (before.element_radius[a], after.element_radius[a])
                };
                o.unwrap() / i.unwrap()
            };
            if thread {
                let p = ratio(2, "period");
                eprintln!("{}: pitch ratio {p:.4}", model.name);
                assert!((p - 2.0).abs() < 0.02, "{}: pitch {p}", model.name);
            } else {
                let (x, y) = (ratio(0, "radius"), ratio(1, "radius"));
                eprintln!(
                    "{} region {}: {} -> {} elements, radius ratio x {x:.4} y {y:.4}",
                    model.name, before.region, before.elements, after.elements
                );
                let tolerance = if model.name == "scaly-blob" {
                    0.05
                } else {
                    0.01
                };
                assert!(
                    (x - 2.0).abs() < 2.0 * tolerance && (y - 1.0).abs() < tolerance,
                    "{} region {}: x {x} y {y}",
                    model.name,
                    before.region
                );
            }
        }
        if model.name == "scaly-blob" {
            // The measure sees the plates, not networks of them: at least half as many
            // elements as over the generator's exact base (112 there; 79 measured; 34
            // when the trend was left in and merged the plates on its high side).
            let (_, graph) = fresco_geotex::graph::prepare(&model.mesh).unwrap();
            let field = fresco_geotex::measure::texture_over(
                &model.mesh,
                &out.input_labels,
                &model.base_mesh,
                &model.mesh.positions,
                &[0.0],
            )
            .unwrap();
            let exact = fresco_geotex::measure::feature_sizes_of(
                &model.mesh,
                &graph,
                &out.input_labels,
                &field,
            );
            let (found, plates) = (m.input.regions[0].elements, exact.regions[0].elements);
            eprintln!(
                "scaly-blob: {found} elements over the faired base, {plates} over the exact base"
            );
            assert!(2 * found >= plates, "{found} elements against {plates}");
        }
    }
}

#[test]
fn bad_targets_are_refused_with_the_axis_named() {
    let mesh = fresco_datasets::shapes::icosphere(1.0, 2);
    for (scale, axis) in [
        ([0.0, 1.0, 1.0], 'x'),
        ([1.0, -2.0, 1.0], 'y'),
        ([1.0, 1.0, f64::NAN], 'z'),
    ] {
        let e = resize(
            &mesh,
            &Target::Scale(scale),
            &ResizeConfig::default(),
            &NoProgress,
        )
        .unwrap_err();
        assert!(
            matches!(e, GeotexError::Target { axis: a, .. } if a == axis),
            "{e}"
        );
        assert!(e.to_string().contains(&format!("along {axis}")), "{e}");
    }
}

#[test]
fn a_mesh_without_texture_is_resized_uniformly_with_a_notice() {
    let mesh = fresco_datasets::shapes::icosphere(1.0, 4);
    let out = resize(
        &mesh,
        &Target::Scale([2.0, 1.0, 1.0]),
        &ResizeConfig::default(),
        &NoProgress,
    )
    .unwrap();
    assert!(out.report.regions.is_empty());
    assert!(out.report.notice.is_some());
    for (p, q) in mesh.positions.iter().zip(&out.mesh.positions) {
        assert!((Point3::new(2.0 * p.x, p.y, p.z) - q).norm() < 1e-9);
    }
}

#[test]
fn an_open_textured_mesh_is_resized_with_its_boundary_following_the_base() {
    // The threaded cylinder with its caps cut off: an open tube.
    let model = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
    let bbox = model.mesh.bounding_box().unwrap();
    let keep = |p: &Point3<f64>| p.z > bbox.min.z + 1e-9 && p.z < bbox.max.z - 1e-9;
    let mut mesh = model.mesh.clone();
    mesh.faces
        .retain(|f| f.iter().any(|&v| keep(&model.mesh.positions[v as usize])));
    let out = resize(
        &mesh,
        &Target::Scale([1.0, 1.0, 2.0]),
        &config(Method::Texture),
        &NoProgress,
    )
    .unwrap();
    assert!(!out.report.regions.is_empty());
    assert!(
        out.mesh
            .positions
            .iter()
            .all(|p| p.coords.iter().all(|c| c.is_finite()))
    );
    let size = out.report.output_size;
    assert!(
        (size[2] / out.report.input_size[2] - 2.0).abs() < 0.02,
        "{size:?}"
    );
}

/// Per seed, per region (small bumps, big bumps) and axis (x, y): the texture method's
/// bump radius out/in; uniform's checked on the way. Computed once for both tests.
fn bump_radius_ratios() -> &'static [[[f64; 2]; 2]] {
    static RATIOS: std::sync::OnceLock<Vec<[[f64; 2]; 2]>> = std::sync::OnceLock::new();
    RATIOS.get_or_init(compute_bump_radius_ratios)
}

fn compute_bump_radius_ratios() -> Vec<[[f64; 2]; 2]> {
    let cfg = gt::BumpyBoxConfig::default();
    let model = gt::bumpy_box(&cfg);
    let target = Target::Scale([2.0, 1.0, 1.0]);
    let uniform = resize(&model.mesh, &target, &config(Method::Uniform), &NoProgress).unwrap();
    let u = uniform.report.measurement.as_ref().unwrap();
    let mut truths = [cfg.small_radius, cfg.big_radius];
    truths.sort_by(f64::total_cmp);
    SEEDS
        .map(|seed| {
            let cfg = ResizeConfig {
                seed,
                ..config(Method::Texture)
            };
            let textured = resize(&model.mesh, &target, &cfg, &NoProgress).unwrap();
            let t = textured.report.measurement.as_ref().unwrap();
            assert_eq!(t.input.regions.len(), 2, "seed {seed}");
            assert_eq!(u.input.regions.len(), 2);
            std::array::from_fn(|k| {
                let before = &t.input.regions[k];
                let after = &t.output.regions[k];
                // Each segmented region is one of the generator's two bump sizes, small
                // first: its measured radius (2 sigma of the part above half its height,
                // about 0.42 of the support radius) says which.
                let r_in = before.element_radius[0].unwrap();
                let truth = truths[k];
                assert!(
                    r_in > 0.35 * truth && r_in < 0.6 * truth,
                    "seed {seed} region {k}: {r_in} vs {truth}"
                );
                assert!(
                    after.elements > before.elements,
                    "the stretched patch holds more bumps"
                );
                // Uniform scaling doubles the radius along x and keeps it along y (the
                // uniform result does not depend on the seed: checked once).
                if seed == 0 {
                    let uni = &u.output.regions[k];
                    let ux = uni.element_radius[0].unwrap() / r_in;
                    assert!((ux - 2.0).abs() < 0.1, "uniform x ratio {ux}");
                    let uy = uni.element_radius[1].unwrap() / before.element_radius[1].unwrap();
                    assert!((uy - 1.0).abs() < 0.05, "uniform y ratio {uy}");
                }
                std::array::from_fn(|a| {
                    after.element_radius[a].unwrap() / before.element_radius[a].unwrap()
                })
            })
        })
        .collect()
}

/// Issue 17's bump line: the texture method keeps both bump sizes along and across the
/// stretch (means over seeds 0-4: small 0.996 / 1.007, big 0.990 / 0.989), uniform
/// doubles them along it. Before session 12 the big bumps came out 3-7% narrow along y
/// (mean 0.949): Kraevoy's grid, protecting the box's edges, made the y slabs 0.84-1.29
/// for a target y scale of 1 and the patch 0.94x as wide; the texture method's grid now
/// lets no region come out relatively smaller (`optimise_keeping_regions`).
#[test]
fn bump_radius_is_kept_by_texture_and_doubled_by_uniform_along_the_stretch() {
    let ratios = bump_radius_ratios();
    for (k, name) in ["small", "big"].iter().enumerate() {
        for (a, axis) in ["x", "y"].iter().enumerate() {
            let r: Vec<f64> = ratios.iter().map(|s| s[k][a]).collect();
            check_ratios(&format!("{name} bumps along {axis}"), &r);
        }
    }
}

/// The same line at every seed (figures at [`check_ratios_strictly`]; the closest is the
/// big bumps along y at seed 3, 0.951).
#[test]
fn bump_radius_is_kept_within_five_percent_at_every_seed() {
    let ratios = bump_radius_ratios();
    for (k, name) in ["small", "big"].iter().enumerate() {
        for (a, axis) in ["x", "y"].iter().enumerate() {
            let r: Vec<f64> = ratios.iter().map(|s| s[k][a]).collect();
            check_ratios_strictly(&format!("{name} bumps along {axis}"), &r);
        }
    }
}

#[test]
fn texture_resize_gives_the_same_bytes_on_one_and_two_threads() {
    // Every parallel step (templates, matching, the least-squares right-hand side over a
    // fixed split, the solves per column, the input and output sides of a level built side
    // by side) must give the same bits whatever the thread count.
    let model = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
    let cfg = ResizeConfig {
        measure: false,
        ..config(Method::Texture)
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                resize(
                    &model.mesh,
                    &Target::Scale([1.0, 1.0, 2.0]),
                    &cfg,
                    &NoProgress,
                )
                .unwrap()
            })
    };
    let (one, two) = (run(1), run(2));
    assert!(!one.report.regions.is_empty() && one.report.split_vertices > 0);
    // The coarsest level ran from every random start and kept the one of lowest energy
    // (the same one on both thread counts, or the bytes below would differ).
    let synthesis = &one.report.synthesis[0];
    let starts = fresco_geotex::SynthesisConfig::default().starts;
    assert_eq!(synthesis.start_energies.len(), starts);
    let lowest = synthesis
        .start_energies
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    assert_eq!(synthesis.start_energies[synthesis.start], lowest);
    assert_eq!(synthesis.start, two.report.synthesis[0].start);
    assert_eq!(one.mesh.faces, two.mesh.faces);
    assert_eq!(one.labels, two.labels);
    let bits = |m: &fresco_core::Mesh| -> Vec<[u64; 3]> {
        m.positions
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            .collect()
    };
    assert!(bits(&one.mesh) == bits(&two.mesh), "positions differ");
}

#[test]
fn texture_resize_carries_rest_positions_on_the_input_surface() {
    // The texture method refines (the thread is stretched 2x along z): the rest mesh must
    // have the output's topology, the input's vertices at their input positions bit for
    // bit, and every vertex the refinement added on the input surface.
    let model = gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default());
    let cfg = ResizeConfig {
        measure: false,
        ..config(Method::Texture)
    };
    let out = resize(
        &model.mesh,
        &Target::Scale([1.0, 1.0, 2.0]),
        &cfg,
        &NoProgress,
    )
    .unwrap();
    let n_in = model.mesh.positions.len();
    assert!(out.report.split_vertices > 0, "nothing was refined");
    let rest = out.rest_mesh();
    assert_eq!(rest.positions.len(), out.mesh.positions.len());
    assert_eq!(rest.faces, out.mesh.faces);
    assert_eq!(n_in + out.report.split_vertices, rest.positions.len());
    assert_eq!(&rest.positions[..n_in], &model.mesh.positions[..]);
    // A created vertex is the midpoint of two points of one input triangle, so it lies on
    // that triangle: its distance is round-off only. Coordinates are at most 2 in size and
    // each midpoint and the closest-point arithmetic lose a few ulps (2.2e-16 relative),
    // so 1e-12 of the diagonal (4.5e-12) is a thousand times that; a created vertex off
    // the input (e.g. a midpoint of two non-neighbouring vertices, or a position taken from
    // the resized output) would be 1e-3 or more away.
    let created = fresco_core::Mesh::from_triangles(rest.positions[n_in..].to_vec(), Vec::new());
    let d = fresco_geotex::measure::distances_to_surface(&created, &model.mesh).unwrap();
    let diagonal = model.mesh.bounding_box().unwrap().diagonal();
    let worst = d.iter().copied().fold(0.0, f64::max);
    assert!(
        worst < 1e-12 * diagonal,
        "a created vertex is {worst} off the input"
    );
    // The rest state is the input's size, not the output's (stretched 2x along z).
    let rest_box = rest.bounding_box().unwrap().extent();
    let in_box = model.mesh.bounding_box().unwrap().extent();
    assert!(
        (rest_box - in_box).norm() < 1e-12,
        "{rest_box:?} vs {in_box:?}"
    );
}

#[test]
fn uniform_and_kraevoy_rest_positions_are_the_input() {
    let mesh = fresco_datasets::shapes::icosphere(1.0, 3);
    for method in [Method::Uniform, Method::Kraevoy] {
        let cfg = ResizeConfig {
            measure: false,
            ..config(method)
        };
        let out = resize(&mesh, &Target::Scale([2.0, 1.0, 1.0]), &cfg, &NoProgress).unwrap();
        assert_eq!(out.rest, mesh.positions, "{method:?}");
        assert_eq!(out.rest_mesh().faces, out.mesh.faces, "{method:?}");
    }
}
