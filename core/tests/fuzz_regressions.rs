//! One test per input the fuzzers of issue 19 found crashing, hanging or exhausting memory in
//! core's readers (`fuzz/`, `bench/fuzz.sh`), built from the minimised input kept in
//! `tests/data/fuzz/`, so that the stable test suite keeps each fixed without the fuzzer.
//! Each names the fuzz target that found it.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fresco_core::ply::{PlyReader, read_mesh};

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

/// Runs `f`, which must return within `limit` (a hang shows up as a failure, not a stall).
fn within<T>(limit: Duration, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    assert!(t.elapsed() < limit, "took {:?}", t.elapsed());
    out
}

/// ply_structured, timeout: `element e128 4000000000` without properties, binary. Each item
/// takes no bytes, and the reader skipped them one at a time: 4 billion iterations reading
/// nothing.
#[test]
fn ply_elements_without_properties_are_skipped_at_once() {
    let path = input("ply_zero_size_element.ply");
    let mesh = within(Duration::from_secs(1), || read_mesh(&path)).unwrap();
    assert!(mesh.positions.is_empty() && mesh.faces.is_empty());
    let r = PlyReader::open(&path).unwrap();
    within(Duration::from_secs(1), || r.finish()).unwrap();
}

/// ply_bytes, crash: a binary PLY whose vertex normal is NaN (an Open3D cloud with one value
/// changed). read_mesh checked positions only and returned a mesh `Mesh::validate` refuses,
/// which no writer could store. Now refused with the vertex named.
#[test]
fn ply_non_finite_normals_are_refused_with_the_vertex_named() {
    let path = input("ply_nan_normal.ply");
    let e = read_mesh(&path).unwrap_err().to_string();
    assert!(
        e.contains("ply_nan_normal.ply") && e.contains("vertex 2") && e.contains("normal"),
        "{e}"
    );
}

/// middlebury, crash: a view name holding vertical tabs (`temp.\v\vleSR0001.png`). The reader
/// splits at ASCII whitespace only and accepted it; `write_par` then refused to store it, so
/// a model read could not be written back. Now refused when read, with the line named.
#[test]
fn par_names_with_whitespace_or_control_characters_are_refused() {
    let path = input("par_name_vertical_tab.txt");
    let e = fresco_core::middlebury::read_par(&path, 640, 480)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("par_name_vertical_tab.txt")
            && e.contains("par_name_vertical_tab.txt:2:")
            && e.contains("whitespace or a control character"),
        "{e}"
    );
}

/// obj, crash: a material library with a `Kd` line of no numbers; tobj 4.0.5 indexes the
/// missing values and panics. The library is now checked first and reported as unreadable:
/// the OBJ is read without materials, as for any library that cannot be read.
#[test]
fn obj_with_a_colour_line_short_of_numbers_reads_without_its_materials() {
    let path = input("obj_short_colour.obj");
    let scene = within(Duration::from_secs(1), || fresco_core::obj::read_obj(&path)).unwrap();
    assert_eq!(scene.mesh.faces.len(), 1);
    assert!(scene.materials.is_empty());
}

/// obj (found while fixing the above): `mtllib /dev/zero` made tobj read a device that never
/// ends. Only regular files are read as material libraries.
#[cfg(unix)]
#[test]
fn obj_naming_a_device_as_material_library_does_not_hang() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("device.obj");
    std::fs::write(
        &path,
        "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let scene = within(Duration::from_secs(1), || fresco_core::obj::read_obj(&path)).unwrap();
    assert_eq!(scene.mesh.faces.len(), 1);
}

/// glb (pst's target, the same gltf 1.4.1 panics in core's read_glb): a 12-byte header
/// declaring 0 bytes (gltf subtracts its header size unchecked) and a primitive naming an
/// accessor the file lacks (gltf's validation looks it up before checking). Both readers now
/// go through `gltf::parse_glb`, which checks them first.
#[test]
fn glb_short_length_and_missing_accessor_are_clear_errors() {
    for (name, says) in [
        ("glb_short_length.glb", "declares 0 bytes"),
        ("glb_accessor_out_of_range.glb", "refers to accessor"),
    ] {
        let e = fresco_core::gltf::read_glb(&input(name))
            .unwrap_err()
            .to_string();
        assert!(e.contains(name) && e.contains(says), "{e}");
    }
}

/// core_glb, crash: a primitive whose TEXCOORD_0 names a VEC3 accessor (a fresco GLB with
/// one index changed). gltf 1.4.1's readers assume the glTF types without checking: an
/// assertion on the item size (8 against 12), or `unreachable!` for other component types.
/// parse_glb now checks each attribute and index accessor's type before anything is read.
#[test]
fn glb_attribute_of_the_wrong_type_is_a_clear_error() {
    let path = input("glb_texcoord_vec3.glb");
    let e = fresco_core::gltf::read_glb(&path).unwrap_err().to_string();
    assert!(
        e.contains("glb_texcoord_vec3.glb")
            && e.contains("TexCoords(0) accessor 1")
            && e.contains("Vec3"),
        "{e}"
    );
}

/// obj, crash: a face `f 1//1 2//1 3//-21474836481` (normal index relative, far before the
/// first normal). tobj 4.0.5 adds it to the count and multiplies unchecked: an overflow panic
/// wherever overflow checks are on. Indices are now checked first, the line named.
#[test]
fn obj_face_index_before_the_first_element_is_refused_with_its_line() {
    let path = input("obj_relative_index_overflow.obj");
    let e = fresco_core::obj::read_obj(&path).unwrap_err().to_string();
    assert!(
        e.contains("obj_relative_index_overflow.obj:5:") && e.contains("normal index -21474836481"),
        "{e}"
    );
}

/// glb (pst's target), crash: an embedded image without `mimeType`, which gltf 1.4.1's
/// `Image::source` unwraps; core's read_glb calls it too.
#[test]
fn glb_image_without_a_mime_type_is_a_clear_error() {
    let path = input("glb_image_without_mime_type.glb");
    let e = fresco_core::gltf::read_glb(&path).unwrap_err().to_string();
    assert!(e.contains("image 0 has neither"), "{e}");
}

/// glb (pst's target), crash: a POSITION accessor of count 0 (a fresco GLB with one digit
/// changed). gltf 1.4.1 computes the accessor's end as `offset + stride * (count - 1) + size`
/// unchecked: an overflow panic where overflow checks are on, a wrapped extent where not.
/// parse_glb now requires count >= 1 and the whole extent inside the buffer view, in checked
/// arithmetic; a huge count is refused the same way.
#[test]
fn glb_accessor_of_count_zero_or_beyond_its_view_is_a_clear_error() {
    let path = input("glb_accessor_count_zero.glb");
    let e = fresco_core::gltf::read_glb(&path).unwrap_err().to_string();
    assert!(
        e.contains("glb_accessor_count_zero.glb") && e.contains("accessor 0: count is 0"),
        "{e}"
    );

    // The same triangle with counts no buffer view of 36 bytes can hold.
    let dir = tempfile::tempdir().unwrap();
    for (count, says) in [
        (4u64, "4 items of 12 bytes"),
        (u64::MAX / 2, "do not fit its buffer view of 36 bytes"),
    ] {
        let path = dir.path().join(format!("count_{count}.glb"));
        std::fs::write(&path, one_triangle_glb(count)).unwrap();
        let e = within(Duration::from_millis(100), || {
            fresco_core::gltf::read_glb(&path)
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains(says), "{e}");
    }
    // The same file with the right count reads.
    let path = dir.path().join("count_3.glb");
    std::fs::write(&path, one_triangle_glb(3)).unwrap();
    let (mesh, _) = fresco_core::gltf::read_glb(&path).unwrap();
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (3, 1));
}

/// A GLB of one triangle whose POSITION accessor declares `count` items over a 36-byte view.
fn one_triangle_glb(count: u64) -> Vec<u8> {
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":36}}],"bufferViews":[{{"buffer":0,"byteLength":36}}],"accessors":[{{"bufferView":0,"count":{count},"componentType":5126,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}]}}"#
    );
    let mut json = json.into_bytes();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let bin: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// obj, crash: `vn 0 0 inf` (tobj parses "inf" and "nan" as numbers). read_obj returned a mesh
/// with a non-finite normal that `Mesh::validate` refuses. Now refused at the `vn` line.
#[test]
fn obj_non_finite_normal_is_refused_with_its_line() {
    let path = input("obj_infinite_normal.obj");
    let e = fresco_core::obj::read_obj(&path).unwrap_err().to_string();
    assert!(
        e.contains("obj_infinite_normal.obj:5:") && e.contains("non-finite"),
        "{e}"
    );
}

/// obj, crash: `vt 0.1e308125 0.75` (an exponent out of range parses as infinity). read_obj
/// returned corner UVs `Mesh::validate` refuses. Now refused at the `vt` line.
#[test]
fn obj_non_finite_texture_coordinate_is_refused_with_its_line() {
    let path = input("obj_infinite_texcoord.obj");
    let e = fresco_core::obj::read_obj(&path).unwrap_err().to_string();
    assert!(
        e.contains("obj_infinite_texcoord.obj:6:") && e.contains("texture coordinate 2"),
        "{e}"
    );
}
