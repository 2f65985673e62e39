//! COLMAP binary models built from arbitrary records in COLMAP's layout (ids, model codes,
//! sizes, parameters, poses, names, keypoints, tracks, rigs and frames), with each count
//! either the true one or an arbitrary u64 (negative as i64, huge, off by one): the reader
//! gets past the headers and meets the inconsistencies a corrupt model holds.
#![no_main]
use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
enum Count {
    True,
    Off(i8),
    Any(u64),
}

impl Count {
    fn put(&self, out: &mut Vec<u8>, n: usize) {
        let v = match self {
            Count::True => n as u64,
            Count::Off(d) => (n as i64 + *d as i64) as u64,
            Count::Any(v) => *v,
        };
        out.extend_from_slice(&v.to_le_bytes());
    }
}

#[derive(Arbitrary, Debug)]
enum Real {
    Small(i8),
    Unit(u8),
    Any(f64),
}

impl Real {
    fn put(&self, out: &mut Vec<u8>) {
        let v = match self {
            Real::Small(i) => *i as f64,
            Real::Unit(u) => *u as f64 / 255.0,
            Real::Any(x) => *x,
        };
        out.extend_from_slice(&v.to_le_bytes());
    }
}

#[derive(Arbitrary, Debug)]
enum Quat {
    Identity,
    Any([Real; 4]),
}

#[derive(Arbitrary, Debug)]
struct Pose {
    q: Quat,
    t: [Real; 3],
}

impl Pose {
    fn put(&self, out: &mut Vec<u8>) {
        match &self.q {
            Quat::Identity => {
                for v in [1.0f64, 0.0, 0.0, 0.0] {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            Quat::Any(q) => q.iter().for_each(|r| r.put(out)),
        }
        self.t.iter().for_each(|r| r.put(out));
    }
}

#[derive(Arbitrary, Debug)]
struct CameraRec {
    id: u8,
    model: i8,
    width: u64,
    height: u64,
    params: Vec<Real>,
}

#[derive(Arbitrary, Debug)]
struct ImageRec {
    id: u8,
    pose: Pose,
    camera_id: u8,
    name: Vec<u8>,
    points: Vec<(Real, Real, Option<u8>)>,
    count: Count,
}

#[derive(Arbitrary, Debug)]
struct PointRec {
    id: u8,
    xyz: [Real; 3],
    rgb: [u8; 3],
    error: Real,
    track: Vec<(u8, u16)>,
    count: Count,
}

#[derive(Arbitrary, Debug)]
struct RigRec {
    id: u8,
    sensors: Vec<(i8, u8, Option<Pose>)>,
}

#[derive(Arbitrary, Debug)]
struct FrameRec {
    id: u8,
    rig: u8,
    pose: Pose,
    data: Vec<(i8, u8, u8)>,
}

#[derive(Arbitrary, Debug)]
struct Model {
    cameras: Vec<CameraRec>,
    cameras_count: Count,
    images: Vec<ImageRec>,
    images_count: Count,
    points: Vec<PointRec>,
    points_count: Count,
    rigs: Option<(Vec<RigRec>, Count, Vec<FrameRec>, Count)>,
    /// Bytes cut from the end of (cameras, images, points).
    cut: [u8; 3],
}

fn cut(mut v: Vec<u8>, n: u8) -> Vec<u8> {
    let keep = v.len().saturating_sub(n as usize % 32);
    v.truncate(keep);
    v
}

fuzz_target!(|m: Model| {
    let mut cams = Vec::new();
    m.cameras_count.put(&mut cams, m.cameras.len());
    for c in &m.cameras {
        cams.extend_from_slice(&(c.id as u32).to_le_bytes());
        cams.extend_from_slice(&(c.model as i32).to_le_bytes());
        cams.extend_from_slice(&c.width.to_le_bytes());
        cams.extend_from_slice(&c.height.to_le_bytes());
        c.params.iter().for_each(|p| p.put(&mut cams));
    }
    let mut imgs = Vec::new();
    m.images_count.put(&mut imgs, m.images.len());
    for im in &m.images {
        imgs.extend_from_slice(&(im.id as u32).to_le_bytes());
        im.pose.put(&mut imgs);
        imgs.extend_from_slice(&(im.camera_id as u32).to_le_bytes());
        imgs.extend_from_slice(&im.name);
        imgs.push(0);
        im.count.put(&mut imgs, im.points.len());
        for (x, y, p) in &im.points {
            x.put(&mut imgs);
            y.put(&mut imgs);
            let id = p.map_or(u64::MAX, |p| p as u64);
            imgs.extend_from_slice(&id.to_le_bytes());
        }
    }
    let mut pts = Vec::new();
    m.points_count.put(&mut pts, m.points.len());
    for p in &m.points {
        pts.extend_from_slice(&(p.id as u64).to_le_bytes());
        p.xyz.iter().for_each(|r| r.put(&mut pts));
        pts.extend_from_slice(&p.rgb);
        p.error.put(&mut pts);
        p.count.put(&mut pts, p.track.len());
        for (image, idx) in &p.track {
            pts.extend_from_slice(&(*image as u32).to_le_bytes());
            pts.extend_from_slice(&(*idx as u32).to_le_bytes());
        }
    }
    let mut data = Vec::new();
    for (k, part) in [cams, imgs, pts].into_iter().enumerate() {
        if k > 0 {
            data.extend_from_slice(fresco_fuzz::FILE_SEPARATOR);
        }
        data.extend_from_slice(&cut(part, m.cut[k]));
    }
    if let Some((rigs, rigs_count, frames, frames_count)) = &m.rigs {
        let mut r = Vec::new();
        rigs_count.put(&mut r, rigs.len());
        for rig in rigs {
            r.extend_from_slice(&(rig.id as u32).to_le_bytes());
            r.extend_from_slice(&(rig.sensors.len() as u32).to_le_bytes());
            for (k, (kind, id, pose)) in rig.sensors.iter().enumerate() {
                r.extend_from_slice(&(*kind as i32 % 3).to_le_bytes());
                r.extend_from_slice(&(*id as u32).to_le_bytes());
                if k > 0 {
                    r.push(pose.is_some() as u8);
                    if let Some(p) = pose {
                        p.put(&mut r);
                    }
                }
            }
        }
        let mut f = Vec::new();
        frames_count.put(&mut f, frames.len());
        for fr in frames {
            f.extend_from_slice(&(fr.id as u32).to_le_bytes());
            f.extend_from_slice(&(fr.rig as u32).to_le_bytes());
            fr.pose.put(&mut f);
            f.extend_from_slice(&(fr.data.len() as u32).to_le_bytes());
            for (kind, sensor, id) in &fr.data {
                f.extend_from_slice(&(*kind as i32 % 3).to_le_bytes());
                f.extend_from_slice(&(*sensor as u32).to_le_bytes());
                f.extend_from_slice(&(*id as u64).to_le_bytes());
            }
        }
        for part in [r, f] {
            data.extend_from_slice(fresco_fuzz::FILE_SEPARATOR);
            data.extend_from_slice(&part);
        }
    }
    fresco_fuzz::dump(&data);
    fresco_fuzz::exercise_colmap(&data, "bin");
});
