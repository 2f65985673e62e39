//! PLY with a well-formed header of arbitrary elements, counts and property types (raw bytes
//! rarely get past the header), then an arbitrary payload: random bytes for the binary
//! formats, lines of numbers for ascii.
#![no_main]
use std::fmt::Write as _;

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
enum Format {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Arbitrary, Debug)]
enum ElementName {
    Vertex,
    Face,
    Other(u8),
}

#[derive(Arbitrary, Debug)]
enum Count {
    Small(u8),
    Any(u64),
    FourBillion,
}

#[derive(Arbitrary, Debug, Clone, Copy)]
enum Ty {
    Char,
    Uchar,
    Short,
    Ushort,
    Int,
    Uint,
    Float,
    Double,
}

#[derive(Arbitrary, Debug)]
enum Kind {
    Scalar(Ty),
    List(Ty, Ty),
}

#[derive(Arbitrary, Debug)]
enum PropName {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    Red,
    Green,
    Blue,
    U,
    V,
    S,
    T,
    VertexIndices,
    VertexIndex,
    Texcoord,
    Texnumber,
    Group,
    Other(u8),
}

#[derive(Arbitrary, Debug)]
struct Property {
    name: PropName,
    kind: Kind,
}

#[derive(Arbitrary, Debug)]
struct Element {
    name: ElementName,
    count: Count,
    properties: Vec<Property>,
}

#[derive(Arbitrary, Debug)]
enum Value {
    Int(i8),
    Wide(i64),
    Real(f32),
    Word(u8),
    Newline,
}

#[derive(Arbitrary, Debug)]
struct Input {
    format: Format,
    /// A vertex element with x, y, z first (the usual file) or only the arbitrary elements.
    usual_vertex: Option<(Ty, Count)>,
    elements: Vec<Element>,
    ascii: Vec<Value>,
    binary: Vec<u8>,
}

fn ty(t: Ty) -> &'static str {
    match t {
        Ty::Char => "char",
        Ty::Uchar => "uchar",
        Ty::Short => "short",
        Ty::Ushort => "ushort",
        Ty::Int => "int",
        Ty::Uint => "uint",
        Ty::Float => "float",
        Ty::Double => "double",
    }
}

fn count(c: &Count) -> u64 {
    match c {
        Count::Small(n) => *n as u64 % 16,
        Count::Any(n) => *n,
        Count::FourBillion => 4_000_000_000,
    }
}

fn prop_name(p: &PropName) -> String {
    match p {
        PropName::X => "x".into(),
        PropName::Y => "y".into(),
        PropName::Z => "z".into(),
        PropName::Nx => "nx".into(),
        PropName::Ny => "ny".into(),
        PropName::Nz => "nz".into(),
        PropName::Red => "red".into(),
        PropName::Green => "green".into(),
        PropName::Blue => "blue".into(),
        PropName::U => "u".into(),
        PropName::V => "v".into(),
        PropName::S => "s".into(),
        PropName::T => "t".into(),
        PropName::VertexIndices => "vertex_indices".into(),
        PropName::VertexIndex => "vertex_index".into(),
        PropName::Texcoord => "texcoord".into(),
        PropName::Texnumber => "texnumber".into(),
        PropName::Group => "group".into(),
        PropName::Other(k) => format!("p{k}"),
    }
}

fuzz_target!(|input: Input| {
    let mut h = String::from("ply\n");
    h.push_str(match input.format {
        Format::Ascii => "format ascii 1.0\n",
        Format::BinaryLittleEndian => "format binary_little_endian 1.0\n",
        Format::BinaryBigEndian => "format binary_big_endian 1.0\n",
    });
    if let Some((t, c)) = &input.usual_vertex {
        let t = ty(*t);
        let _ = writeln!(h, "element vertex {}", count(c));
        let _ = writeln!(h, "property {t} x\nproperty {t} y\nproperty {t} z");
    }
    for e in input.elements.iter().take(4) {
        let name = match e.name {
            ElementName::Vertex => "vertex".to_string(),
            ElementName::Face => "face".to_string(),
            ElementName::Other(k) => format!("e{k}"),
        };
        let _ = writeln!(h, "element {name} {}", count(&e.count));
        for p in e.properties.iter().take(12) {
            match p.kind {
                Kind::Scalar(t) => {
                    let _ = writeln!(h, "property {} {}", ty(t), prop_name(&p.name));
                }
                Kind::List(c, t) => {
                    let _ = writeln!(
                        h,
                        "property list {} {} {}",
                        ty(c),
                        ty(t),
                        prop_name(&p.name)
                    );
                }
            }
        }
    }
    h.push_str("end_header\n");
    let mut bytes = h.into_bytes();
    match input.format {
        Format::Ascii => {
            let mut s = String::new();
            for v in &input.ascii {
                match v {
                    Value::Int(i) => {
                        let _ = write!(s, "{i} ");
                    }
                    Value::Wide(i) => {
                        let _ = write!(s, "{i} ");
                    }
                    Value::Real(x) => {
                        let _ = write!(s, "{x} ");
                    }
                    Value::Word(w) => s.push_str(
                        ["nan ", "inf ", "-1 ", "1e400 ", "0x10 ", "\t", "\r\n", "é "]
                            [*w as usize % 8],
                    ),
                    Value::Newline => s.push('\n'),
                }
            }
            bytes.extend_from_slice(s.as_bytes());
        }
        _ => bytes.extend_from_slice(&input.binary),
    }
    fresco_fuzz::exercise_ply(&bytes);
});
