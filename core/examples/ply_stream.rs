//! Streams a large PLY file through fresco's PLY writer and reader (used by
//! `bench/ply_stream.sh`).
//!
//! ```text
//! ply_stream write <out.ply> <grid side n> [ascii|le|be]   # n*n vertices, 2(n-1)^2 triangles
//! ply_stream read <in.ply>                                 # streams it, prints figures as JSON
//! ```
//! The grid is a height field with per-vertex colours, written one vertex and one triangle at
//! a time, so memory stays flat however large `n` is.

use std::time::Instant;

use fresco_core::nalgebra::Point3;
use fresco_core::ply::{PlyFormat, PlyLayout, PlyReader, PlyVertex, PlyWriter};

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("write") if args.len() >= 4 => {
            let n: u32 = args[3].parse()?;
            let format = match args.get(4).map(String::as_str) {
                Some("ascii") => PlyFormat::Ascii,
                Some("be") => PlyFormat::BinaryBigEndian,
                _ => PlyFormat::BinaryLittleEndian,
            };
            write(&args[2], n, format)
        }
        Some("read") if args.len() >= 3 => read(&args[2]),
        _ => Err(
            "usage: ply_stream write <out.ply> <n> [ascii|le|be] | ply_stream read <in.ply>".into(),
        ),
    }
}

fn write(path: &str, n: u32, format: PlyFormat) -> Result<(), Box<dyn std::error::Error>> {
    let start = Instant::now();
    let nv = n as u64 * n as u64;
    let nf = 2 * (n as u64 - 1) * (n as u64 - 1);
    let mut layout = PlyLayout::new(format, nv, nf);
    layout.colors = true;
    let mut w = PlyWriter::create(path, layout)?;
    let mut v = PlyVertex::new(Point3::origin());
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            v.position = Point3::new(x, y, 0.1 * (6.0 * x).sin() * (4.0 * y).cos());
            v.color = Some([(i & 255) as u8, (j & 255) as u8, ((i ^ j) & 255) as u8]);
            w.write_vertex(&v)?;
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            w.write_triangle([a, a + 1, a + n + 1])?;
            w.write_triangle([a, a + n + 1, a + n])?;
        }
    }
    w.finish()?;
    let bytes = std::fs::metadata(path)?.len();
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{{\"op\":\"write\",\"vertices\":{nv},\"faces\":{nf},\"bytes\":{bytes},\"seconds\":{secs:.3},\"mb_per_s\":{:.1}}}",
        bytes as f64 / 1e6 / secs
    );
    Ok(())
}

fn read(path: &str) -> Result<(), Box<dyn std::error::Error>> {
    let start = Instant::now();
    let bytes = std::fs::metadata(path)?.len();
    let mut r = PlyReader::open(path)?;
    let mut vertices = 0u64;
    let mut checksum = 0.0f64;
    let mut colour_sum = 0u64;
    let mut buf = Vec::with_capacity(1 << 16);
    while r.read_vertices(&mut buf, 1 << 16)? > 0 {
        for v in &buf {
            checksum += v.position.z;
            colour_sum += v.color.map_or(0, |c| c[0] as u64);
        }
        vertices += buf.len() as u64;
    }
    let t_vertices = start.elapsed().as_secs_f64();
    let mut faces = 0u64;
    let mut index_sum = 0u64;
    for t in r.triangles() {
        let t = t?;
        index_sum += t[2] as u64;
        faces += 1;
    }
    r.finish()?;
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{{\"op\":\"read\",\"vertices\":{vertices},\"faces\":{faces},\"bytes\":{bytes},\"seconds\":{secs:.3},\
         \"vertex_seconds\":{t_vertices:.3},\"mb_per_s\":{:.1},\"vertices_per_s\":{:.0},\"faces_per_s\":{:.0},\
         \"checksum\":{checksum:.6},\"colour_sum\":{colour_sum},\"index_sum\":{index_sum}}}",
        bytes as f64 / 1e6 / secs,
        vertices as f64 / t_vertices,
        faces as f64 / (secs - t_vertices)
    );
    Ok(())
}
