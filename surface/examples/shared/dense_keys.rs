//! The `key=value` overrides of the dense examples (`dense_synth`, `dense_view_bench`,
//! `dense_tune`): one list of the settings they can change.

use fresco_surface::dense::DenseConfig;

/// Sets the setting `key` of `config` to `value`, or says the key is unknown.
pub fn set_dense_key(
    config: &mut DenseConfig,
    key: &str,
    value: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let pm = &mut config.patch_match;
    match key {
        "max_image_size" => config.max_image_size = value.parse()?,
        "geometric" => config.geometric = value.parse()?,
        "scales" => pm.scales = value.parse()?,
        "iterations" => pm.iterations = value.parse()?,
        "fine_iterations" => pm.fine_iterations = value.parse()?,
        "finest_iterations" => pm.finest_iterations = value.parse()?,
        "geometric_iterations" => pm.geometric_iterations = value.parse()?,
        "settled_px" => pm.settled_px = value.parse()?,
        "still_depth" => pm.still_depth = value.parse()?,
        "still_normal_deg" => pm.still_normal_deg = value.parse()?,
        "adaptive_views" => pm.adaptive_views = value.parse()?,
        "top_k" => pm.top_k = value.parse()?,
        "window_radius" => pm.window_radius = value.parse()?,
        "window_step" => pm.window_step = value.parse()?,
        "sigma_color" => pm.sigma_color = value.parse()?,
        "sigma_spatial" => pm.sigma_spatial = value.parse()?,
        "max_cost" => pm.max_cost = value.parse()?,
        "min_ref_std" => pm.min_ref_std = value.parse()?,
        "max_sources" => config.view_selection.max_sources = value.parse()?,
        "min_views" => config.fusion.min_views = value.parse()?,
        "one_short_if_clear" => config.fusion.one_short_if_clear = value.parse()?,
        "max_reproj_px" => config.fusion.max_reproj_px = value.parse()?,
        "max_depth_error" => config.fusion.max_depth_error = value.parse()?,
        "max_normal_deg" => config.fusion.max_normal_deg = value.parse()?,
        "free_space" => config.fusion.free_space = value.parse()?,
        "support_plane" => config.fusion.support_plane.remove = value.parse()?,
        _ => return Err(format!("unknown key {key}").into()),
    }
    Ok(())
}
