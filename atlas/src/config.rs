//! Settings of [`crate::texture_mesh`], with their defaults in one place
//! ([`TextureConfig::default`]) and a [`TextureConfig::check`] that names the bad field.

use serde::Serialize;

use crate::TextureError;

/// Settings of the texture reconstruction.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TextureConfig {
    /// Largest width and height of an atlas image, texels. Default 8192.
    pub max_atlas_size: u32,
    /// Most atlas images written; never exceeded (the density drops instead, with a
    /// warning). Default 1.
    pub max_atlases: u32,
    /// Texels between charts and from the atlas border when the mesh is unwrapped here.
    /// Default 4.
    pub gutter: u32,
    /// Texel density relative to the best photo that sees the surface: texels per photo
    /// pixel along a side. Default 1.5: a viewer's bilinear lookup of texels at the photos'
    /// own resolution blurs what they resolve, which sharpening undoes only in part
    /// (`playback_sharpening`); half again as many texels per side gain 0.3-0.8 dB held out
    /// on the synthetic scenes for 2.25x the texels (`bench/RESULTS.md` issue 14, session 9).
    pub texels_per_pixel: f64,
    /// Texels per world unit, overriding the density chosen from the photos. Default none.
    pub texels_per_unit: Option<f64>,
    /// Views seeing a face at more than this angle from its normal are dropped for it
    /// (grazing and back-facing views), degrees. Default 80.
    pub max_view_angle_deg: f64,
    /// Relative depth tolerance of the visibility test (a surface point is seen when the
    /// depth buffer around its pixel is within this fraction of its depth, plus two pixel
    /// footprints along the slope). Default 0.005.
    pub depth_tolerance: f64,
    /// Fit a gain per view and colour channel on the overlaps (exposure and white balance).
    /// Default true.
    pub exposure_gains: bool,
    /// Drop, per texel, a view whose colour disagrees with the others (highlights,
    /// occluders). Default true.
    pub outlier_rejection: bool,
    /// A view is an outlier at a texel when it is further than this many robust standard
    /// deviations (1.4826 MAD) from the median of the views, and further than
    /// [`TextureConfig::outlier_min_difference`]. Default 3.
    pub outlier_sigmas: f64,
    /// Smallest colour difference (max over channels, in [0, 1]) that can make an outlier.
    /// Default 0.12 (about 30/255).
    pub outlier_min_difference: f64,
    /// Texels of misregistration the outlier test tolerates: a view's colour is compared
    /// with the range (per-channel minimum to maximum) the other views show within this many
    /// texels, so that an edge of the photos' content displaced by a slightly wrong surface
    /// does not count as disagreement (0: compare colours at the texel only). Texels at one
    /// texel per photo pixel, scaled by `texels_per_pixel` above 1. Default 2.
    pub outlier_window: u32,
    /// A view that disagrees with the consensus still counts as consistent when it agrees
    /// with another view seeing the face from within this angle, degrees: a wrong surface
    /// shifts what nearby views see alike, while a highlight or occluder of one photo is in
    /// that photo only (0: no such exception). Default 45 (real temple, views about 22 deg
    /// apart on a ring: 25 deg recovers less, `bench/RESULTS.md` issue 14 session 4).
    pub outlier_neighbour_deg: f64,
    /// A view's rejection is kept at a texel only when it lies within two texels of a patch:
    /// a texel where at least this fraction of the view's texels within two texels are
    /// rejected too (a highlight or occluder is a patch, while a wrong surface makes views
    /// disagree along thin lines, the edges of the content). 0 keeps every rejection.
    /// Default 0.8.
    pub outlier_patch_fraction: f64,
    /// Weight of the view-quality preference per texel against Kwatra's seam cost in the
    /// graph cuts. Default 0.2.
    pub quality_weight: f64,
    /// Regularises Kwatra's gradient denominator in flat regions (colour units). Default 0.05.
    pub seam_epsilon: f64,
    /// Sweeps of param's stretch optimisation when the mesh is unwrapped here (param's own
    /// default is 6, for the lowest stretch; a texture needs charts that are near-isometric,
    /// not optimal, and the sweeps are most of the unwrap's time on large meshes). Default 2.
    pub unwrap_stretch_iterations: u32,
    /// Read the photos with a bicubic (Catmull-Rom) lookup instead of a bilinear one (the
    /// bilinear lookup blurs detail at the photo's pixel scale). Default true (held-out PSNR,
    /// 640x480, gain-fitted, views 5 / 17: torus +1.3 / +1.2 dB, temple +0.6 / +0.8, blob
    /// +1.2 / +1.1).
    pub bicubic: bool,
    /// Pyramid levels subtracted from the level whose pixel is one texel's footprint
    /// (0: the footprint level; 0.5: sharper, a little aliasing when a view is finer than the
    /// texels), in [0, 4]. Default 0.5 (held-out PSNR, 640x480, gain-fitted, views 5 / 17:
    /// torus +0.3 / +0.4 dB, blob +0.3 / +0.2, temple unchanged, whose views are all coarser
    /// than its texels).
    pub mip_bias: f64,
    /// Blend, per texel, the graph cut's view with the other views that see it nearly as
    /// well and agree with it (`fusion.rs`). Default true.
    pub blend_views: bool,
    /// Smallest quality of a blended view relative to the best view of the face, in [0, 1].
    /// Default 0.5.
    pub blend_min_quality: f64,
    /// Largest difference (any channel, colour in [0, 1], after the gains) between a blended
    /// view and the cut's view at a texel. Default 0.08 (about 20/255).
    pub blend_tolerance: f64,
    /// The blend's tolerance grows to this many robust standard deviations of the views'
    /// distances to the cut's colour where they scatter more than `blend_tolerance` (0: the
    /// fixed tolerance). Default 2.
    pub blend_sigmas: f64,
    /// A view's weight ramps up over this many texels from the edge of the region where it
    /// is valid (at one texel per photo pixel, scaled by `texels_per_pixel` above 1).
    /// Default 4.
    pub blend_fade_texels: f64,
    /// Level the colours across chart boundaries after fusion (`leveling.rs`: per chart and
    /// vertex offsets by least squares), before the seam strip. Default false: without the
    /// strip it lowered the real temple's seam discrepancy from 21.0 to 15.8 with the
    /// held-out PSNR unchanged (+-0.05 dB), but it carries a painted highlight's influence
    /// along the seams (mean difference 3.6/255 inside the disc, over the 3).
    pub seam_leveling: bool,
    /// Weight of the smoothness of the leveling offsets along each edge inside a chart,
    /// against a seam edge's colour difference (weight 1). Default 0.1.
    pub seam_leveling_smoothness: f64,
    /// Width of the strip along the seams (chart boundaries) over which each side is brought
    /// to the mean level of both (each seam edge's median step), fading from the full
    /// correction at the seam to none at this many texels inside the chart (`leveling.rs`,
    /// `seam_strip`); 0 turns it off. Default 0 (off): on the real temple it costs SSIM
    /// (0.005 / 0.009) for little (seams 9.5 -> 8.3 after the detail passes).
    pub seam_strip_texels: f64,
    /// Passes that then close the remaining step at every texel along the seams, over the two
    /// texels next to them (each pass closes about half of what remains: the texels around a
    /// seam point are shared with its neighbours); 0 turns them off. Default 2 (real temple,
    /// 200k faces, held out 0005 / 0013: seam discrepancy 24.2 -> 9.5, below MeshLab's
    /// 13.2, gain-fitted PSNR 16.50 / 19.20 -> 16.53 / 19.19 dB, SSIM -0.008 / -0.013;
    /// one pass gives 13.3).
    pub seam_detail_passes: u32,
    /// The seam strip leaves alone the seam edges whose two faces meet at more than this
    /// angle, degrees (180: none left alone): across a sharp crease the two sides are lit
    /// differently and the colour step is the surface's. Default 60 (synthetic temple, whose
    /// seams lie on its 90-degree creases, 640x480, gain-fitted: 33.07 / 33.27 -> 33.46 /
    /// 33.66 dB, the same at 30; real temple: PSNR unchanged, seam discrepancy 9.73 ->
    /// 10.26, MeshLab param 13.92).
    pub seam_strip_crease_deg: f64,
    /// How much of the playback blur the finished atlas' photo texels are sharpened against,
    /// 1 = all of it, 0 = off. Default 1. The blur: a viewer's bilinear lookup and the photo
    /// pixel each texel was read from; the strength `a` of the sharpening
    /// `(1 + 4a) c - a (4 neighbours)` that undoes it is `1/6 + t^2 / 16` for `t` texels per
    /// photo pixel, faded by the views' mean squared misregistration measured in pixels
    /// (none from one pixel on: detail the views do not agree on is not amplified;
    /// `texture.rs`, `sharpening_strength`). Synthetic torus / temple / blob at 640x480, views
    /// 5 / 17 held out, gain-fitted: 37.16 / 32.35 / 37.43 dB unsharpened; 38.67 / 33.56 /
    /// 39.25 with the session-6 fixed `a = 1/6`; session 9's rule and 1.5 texels per pixel in
    /// `bench/RESULTS.md` issue 14. The real temple gets none: its views are 1.1 pixels^2 apart.
    pub playback_sharpening: f64,
    /// Images (by name) kept out of the texture, e.g. held out for evaluation. Default empty.
    pub exclude_images: Vec<String>,
    /// Also write `model.obj` + `model.mtl` beside the GLB. Default false.
    pub write_obj: bool,
}

impl Default for TextureConfig {
    fn default() -> Self {
        TextureConfig {
            max_atlas_size: 8192,
            max_atlases: 1,
            gutter: 4,
            texels_per_pixel: 1.5,
            texels_per_unit: None,
            max_view_angle_deg: 80.0,
            depth_tolerance: 0.005,
            exposure_gains: true,
            outlier_rejection: true,
            outlier_sigmas: 3.0,
            outlier_min_difference: 0.12,
            outlier_window: 2,
            outlier_neighbour_deg: 45.0,
            outlier_patch_fraction: 0.8,
            quality_weight: 0.2,
            seam_epsilon: 0.05,
            unwrap_stretch_iterations: 2,
            bicubic: true,
            mip_bias: 0.5,
            blend_views: true,
            blend_min_quality: 0.5,
            blend_tolerance: 0.08,
            blend_sigmas: 2.0,
            blend_fade_texels: 4.0,
            seam_leveling: false,
            seam_leveling_smoothness: 0.1,
            seam_strip_texels: 0.0,
            seam_detail_passes: 2,
            playback_sharpening: 1.0,
            seam_strip_crease_deg: 60.0,
            exclude_images: Vec::new(),
            write_obj: false,
        }
    }
}

impl TextureConfig {
    /// Checks every field; the error names the first one out of range.
    pub fn check(&self) -> Result<(), TextureError> {
        let bad =
            |field: &'static str, message: String| Err(TextureError::Config { field, message });
        if !(64..=32768).contains(&self.max_atlas_size) {
            return bad(
                "max_atlas_size",
                format!("{} is outside 64..=32768 texels", self.max_atlas_size),
            );
        }
        if self.max_atlases == 0 {
            return bad("max_atlases", "at least one atlas is needed".into());
        }
        if 4 * self.gutter + 8 > self.max_atlas_size {
            return bad(
                "gutter",
                format!(
                    "{} texels leave no room in a {} atlas",
                    self.gutter, self.max_atlas_size
                ),
            );
        }
        if !(self.texels_per_pixel.is_finite()
            && self.texels_per_pixel > 0.0
            && self.texels_per_pixel <= 16.0)
        {
            return bad(
                "texels_per_pixel",
                format!("{} is outside (0, 16]", self.texels_per_pixel),
            );
        }
        if let Some(t) = self.texels_per_unit
            && !(t.is_finite() && t > 0.0)
        {
            return bad("texels_per_unit", format!("{t} is not a positive number"));
        }
        if !(self.max_view_angle_deg > 0.0 && self.max_view_angle_deg < 90.0) {
            return bad(
                "max_view_angle_deg",
                format!("{} is outside (0, 90) degrees", self.max_view_angle_deg),
            );
        }
        if !(self.depth_tolerance.is_finite() && (0.0..0.5).contains(&self.depth_tolerance)) {
            return bad(
                "depth_tolerance",
                format!("{} is outside [0, 0.5)", self.depth_tolerance),
            );
        }
        if !(self.outlier_sigmas.is_finite() && self.outlier_sigmas > 0.0) {
            return bad(
                "outlier_sigmas",
                format!("{} is not a positive number", self.outlier_sigmas),
            );
        }
        if !(self.outlier_min_difference.is_finite()
            && (0.0..=1.0).contains(&self.outlier_min_difference))
        {
            return bad(
                "outlier_min_difference",
                format!("{} is outside [0, 1]", self.outlier_min_difference),
            );
        }
        if self.outlier_window > 8 {
            return bad(
                "outlier_window",
                format!("{} is outside 0..=8 texels", self.outlier_window),
            );
        }
        if !(self.outlier_neighbour_deg.is_finite()
            && (0.0..=90.0).contains(&self.outlier_neighbour_deg))
        {
            return bad(
                "outlier_neighbour_deg",
                format!("{} is outside [0, 90] degrees", self.outlier_neighbour_deg),
            );
        }
        if !(self.outlier_patch_fraction.is_finite()
            && (0.0..=1.0).contains(&self.outlier_patch_fraction))
        {
            return bad(
                "outlier_patch_fraction",
                format!("{} is outside [0, 1]", self.outlier_patch_fraction),
            );
        }
        if !(self.quality_weight.is_finite() && self.quality_weight >= 0.0) {
            return bad(
                "quality_weight",
                format!("{} is not a non-negative number", self.quality_weight),
            );
        }
        if !(self.seam_epsilon.is_finite() && self.seam_epsilon > 0.0) {
            return bad(
                "seam_epsilon",
                format!("{} is not a positive number", self.seam_epsilon),
            );
        }
        if !(self.mip_bias.is_finite() && (0.0..=4.0).contains(&self.mip_bias)) {
            return bad("mip_bias", format!("{} is outside [0, 4]", self.mip_bias));
        }
        if !(self.blend_min_quality.is_finite() && (0.0..=1.0).contains(&self.blend_min_quality)) {
            return bad(
                "blend_min_quality",
                format!("{} is outside [0, 1]", self.blend_min_quality),
            );
        }
        if !(self.blend_tolerance.is_finite() && (0.0..=1.0).contains(&self.blend_tolerance)) {
            return bad(
                "blend_tolerance",
                format!("{} is outside [0, 1]", self.blend_tolerance),
            );
        }
        if !(self.blend_sigmas.is_finite() && (0.0..=10.0).contains(&self.blend_sigmas)) {
            return bad(
                "blend_sigmas",
                format!("{} is outside [0, 10]", self.blend_sigmas),
            );
        }
        if !(self.blend_fade_texels.is_finite() && (1.0..=64.0).contains(&self.blend_fade_texels)) {
            return bad(
                "blend_fade_texels",
                format!("{} is outside [1, 64]", self.blend_fade_texels),
            );
        }
        if !(self.seam_leveling_smoothness.is_finite()
            && self.seam_leveling_smoothness > 0.0
            && self.seam_leveling_smoothness <= 1e3)
        {
            return bad(
                "seam_leveling_smoothness",
                format!("{} is outside (0, 1000]", self.seam_leveling_smoothness),
            );
        }
        if !(self.seam_strip_texels.is_finite() && (0.0..=64.0).contains(&self.seam_strip_texels)) {
            return bad(
                "seam_strip_texels",
                format!("{} is outside [0, 64] texels", self.seam_strip_texels),
            );
        }
        if !(self.playback_sharpening.is_finite()
            && (0.0..=1.0).contains(&self.playback_sharpening))
        {
            return bad(
                "playback_sharpening",
                format!("{} is outside [0, 1]", self.playback_sharpening),
            );
        }
        if !(self.seam_strip_crease_deg.is_finite()
            && (0.0..=180.0).contains(&self.seam_strip_crease_deg))
        {
            return bad(
                "seam_strip_crease_deg",
                format!("{} is outside [0, 180] degrees", self.seam_strip_crease_deg),
            );
        }
        if self.seam_detail_passes > 8 {
            return bad(
                "seam_detail_passes",
                format!("{} is outside 0..=8", self.seam_detail_passes),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn documented_defaults_hold_and_pass_the_check() {
        let c = TextureConfig::default();
        assert_eq!(c.max_atlas_size, 8192);
        assert_eq!(c.max_atlases, 1);
        assert_eq!(c.gutter, 4);
        assert_eq!(c.texels_per_pixel, 1.5);
        assert_eq!(c.max_view_angle_deg, 80.0);
        assert!(c.exposure_gains && c.outlier_rejection);
        assert!(c.bicubic);
        assert_eq!(c.mip_bias, 0.5);
        assert_eq!(c.unwrap_stretch_iterations, 2);
        assert!(c.blend_views);
        assert!(!c.seam_leveling);
        assert_eq!(c.blend_min_quality, 0.5);
        assert_eq!(c.blend_tolerance, 0.08);
        assert_eq!(c.blend_fade_texels, 4.0);
        assert_eq!(c.blend_sigmas, 2.0);
        assert_eq!(c.outlier_window, 2);
        assert_eq!(c.outlier_neighbour_deg, 45.0);
        assert_eq!(c.outlier_patch_fraction, 0.8);
        assert_eq!(c.seam_leveling_smoothness, 0.1);
        assert_eq!(c.seam_strip_texels, 0.0);
        assert_eq!(c.seam_detail_passes, 2);
        assert_eq!(c.playback_sharpening, 1.0);
        assert_eq!(c.seam_strip_crease_deg, 60.0);
        assert!(c.exclude_images.is_empty());
        c.check().unwrap();
    }

    #[test]
    fn check_names_the_bad_field() {
        let c = TextureConfig {
            max_view_angle_deg: 95.0,
            ..TextureConfig::default()
        };
        let e = c.check().unwrap_err().to_string();
        assert!(e.contains("max_view_angle_deg"), "{e}");
        let c = TextureConfig {
            texels_per_pixel: f64::NAN,
            ..TextureConfig::default()
        };
        assert!(
            c.check()
                .unwrap_err()
                .to_string()
                .contains("texels_per_pixel")
        );
    }
}
