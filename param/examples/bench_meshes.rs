//! Writes the meshes bench/param.sh unwraps: `cargo run --release -p fresco-param --example
//! bench_meshes -- <folder>` -> sphere.ply, torus.ply, double_torus.ply, temple.ply and
//! torus_200k.ply (a 448 x 224 torus, 200,704 faces).

use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_datasets::{Shape, shapes};

fn main() {
    let dir = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .expect("usage: bench_meshes <folder>"),
    );
    std::fs::create_dir_all(&dir).expect("creating the output folder");
    let meshes = [
        ("sphere", Shape::Sphere.mesh(2)),
        ("torus", Shape::Torus.mesh(1)),
        ("double_torus", Shape::DoubleTorus.mesh(0)),
        ("temple", Shape::Temple.mesh(1)),
        ("torus_200k", shapes::torus(0.7, 0.3, 448, 224)),
    ];
    for (name, mesh) in meshes {
        let path = dir.join(format!("{name}.ply"));
        write_mesh(&path, &mesh, PlyFormat::BinaryLittleEndian).expect("writing a mesh");
        println!("{} {} faces", path.display(), mesh.faces.len());
    }
}
