//! Copies a photo folder with every second photo (even-numbered in name order) down-scaled
//! to 75% by the `image` crate's triangle (bilinear) filter: a set from two cameras of
//! different sizes, as `cli/tests/run_bad_input.rs` builds it. For bench/sfm_mixed.sh.
//!
//! Usage: mixed_size_photos <photos> <out>

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, photos, out] = &args[..] else {
        return Err("usage: mixed_size_photos <photos> <out>".into());
    };
    std::fs::create_dir_all(out)?;
    let mut names: Vec<std::path::PathBuf> = std::fs::read_dir(photos)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png" || x == "jpg"))
        .collect();
    names.sort();
    for (k, p) in names.iter().enumerate() {
        let dst = std::path::Path::new(out).join(p.file_name().ok_or("no file name")?);
        if k % 2 == 1 {
            let img = image::open(p)?.to_rgb8();
            let (w, h) = (img.width() * 3 / 4, img.height() * 3 / 4);
            image::imageops::resize(&img, w, h, image::imageops::FilterType::Triangle)
                .save(&dst)?;
        } else {
            std::fs::copy(p, &dst)?;
        }
    }
    Ok(())
}
