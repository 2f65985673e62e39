//! The views of a dense workspace's undistorted model (`<dense>/sparse`), in the model's
//! image order, for the dense examples.

use fresco_core::Reconstruction;
use fresco_surface::dense::DenseView;

/// One [`DenseView`] per image of `rec` (its camera and pose as the model stores them).
pub fn dense_views(rec: &Reconstruction) -> Vec<DenseView> {
    rec.images
        .values()
        .map(|im| DenseView {
            image_id: im.id,
            name: im.name.clone(),
            camera: rec.cameras[&im.camera_id].clone(),
            cam_from_world: im.cam_from_world,
        })
        .collect()
}
