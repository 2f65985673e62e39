//! End-to-end check of issue 7: colours of a textured model of a shape, transferred through a
//! PST onto a huge mesh of the same shape, compared with the ground-truth albedo at the huge
//! mesh's vertices (PSNR, 8-bit RGB).
//!
//! `cargo run --release -p fresco-pst --example pst_e2e -- <huge.ply> <work dir> [n] [model m]`
//!
//! The model is the same displaced sphere (`fresco_datasets::large_mesh`) at 1280 m^2
//! triangles (default m = 32: 1.3M triangles), coloured per vertex by
//! `fresco_datasets::Albedo` and written as OBJ with vertex colours; the huge mesh is sampled
//! to n points (default 400 000), coloured from the model, applied back (k = 8) and read
//! again. The defaults are the configuration of the issue 7 row in bench/RESULTS.md.

use std::path::PathBuf;
use std::time::Instant;

use fresco_core::NoProgress;
use fresco_core::nalgebra::Point3;
use fresco_core::ply::PlyReader;
use fresco_datasets::Albedo;
use fresco_datasets::large_mesh::LargeMesh;
use fresco_pst::apply::{ApplyConfig, apply_to_ply};
use fresco_pst::paint::{Op, apply_op};
use fresco_pst::region::Region;
use fresco_pst::{CreateConfig, FieldConfig, PlyPoints, Pst, SamplingConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: pst_e2e <huge.ply> <work dir> [n] [model m]".into());
    }
    let huge = PathBuf::from(&args[1]);
    let work = PathBuf::from(&args[2]);
    let n: u64 = args.get(3).map_or(Ok(400_000), |s| s.parse())?;
    let m: u32 = args.get(4).map_or(Ok(32), |s| s.parse())?;
    std::fs::create_dir_all(&work)?;
    // The albedo's pattern (checker, stripes, patches, noise) stretched 3x: features of about
    // 0.5 units on a shape 2.4 units across.
    let albedo = Albedo::new(7, 3.0);

    let t = Instant::now();
    let mut model = LargeMesh::new(3, m).to_mesh();
    model.colors = Some(model.positions.iter().map(|p| albedo.at_u8(p)).collect());
    let model_path = work.join("model.obj");
    fresco_core::obj::write_obj(&model_path, &model, &[])?;
    println!(
        "model: {} triangles, {:.1} s",
        model.faces.len(),
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let source = PlyPoints::open(&huge)?;
    let cfg = CreateConfig {
        sampling: SamplingConfig {
            target: n,
            ..Default::default()
        },
        ..Default::default()
    };
    let pst_dir = work.join("e2e.pst");
    let (mut pst, s) = Pst::create(&source, &cfg, &pst_dir, &NoProgress)?;
    println!(
        "sampled {} points to {} samples in {:.1} s",
        s.input_points,
        s.samples.len(),
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    // Absolute: ops resolve relative paths against the script's folder (here `work`).
    let op = Op::Transfer {
        model: std::path::absolute(&model_path)?,
        max_distance: None,
        region: Region::All,
        channel: "rgb".into(),
    };
    apply_op(&mut pst, &op, &work, FieldConfig::default(), &NoProgress)?;
    pst.save()?;
    println!("transfer: {:.1} s", t.elapsed().as_secs_f64());

    let t = Instant::now();
    let out = work.join("colored.ply");
    let r = apply_to_ply(&pst, &huge, &out, &ApplyConfig::default(), &NoProgress)?;
    println!(
        "apply: {} vertices in {:.1} s",
        r.vertices,
        t.elapsed().as_secs_f64()
    );

    // PSNR of the applied colours against the albedo at every vertex.
    let mut reader = PlyReader::open(&out)?;
    let mut buf = Vec::new();
    let (mut sse, mut count) = (0f64, 0u64);
    let (mut sse_model, mut count_model) = (0f64, 0u64);
    loop {
        let got = reader.read_vertices(&mut buf, 1 << 20)?;
        if got == 0 {
            break;
        }
        for v in &buf {
            let truth = albedo.at_u8(&Point3::new(v.position.x, v.position.y, v.position.z));
            let c = v.color.ok_or("no colour in the output")?;
            for k in 0..3 {
                sse += (c[k] as f64 - truth[k] as f64).powi(2);
            }
            count += 3;
        }
    }
    // The model itself, at its own vertices' midpoints (how well it carries the albedo).
    for f in model.faces.iter().step_by(7) {
        let p = Point3::from(
            (model.positions[f[0] as usize].coords
                + model.positions[f[1] as usize].coords
                + model.positions[f[2] as usize].coords)
                / 3.0,
        );
        let truth = albedo.at_u8(&p);
        let cols = model.colors.as_ref().expect("coloured");
        for k in 0..3 {
            let mean = (cols[f[0] as usize][k] as f64
                + cols[f[1] as usize][k] as f64
                + cols[f[2] as usize][k] as f64)
                / 3.0;
            sse_model += (mean - truth[k] as f64).powi(2);
        }
        count_model += 3;
    }
    let psnr = |sse: f64, n: u64| 10.0 * (255.0f64.powi(2) / (sse / n as f64)).log10();
    println!(
        "{{\"vertices\": {}, \"samples\": {}, \"psnr_db\": {:.2}, \"model_psnr_db\": {:.2}}}",
        count / 3,
        pst.samples.len(),
        psnr(sse, count),
        psnr(sse_model, count_model)
    );
    Ok(())
}
