//! Where a box of the scene can land on the film: its sharp image through the lens centre and
//! the range of blur over its depths. Light tracing sizes its light paths by it
//! ([`crate::render::light_choice`]); the site rule finds what the depth pass cannot see with it
//! ([`crate::render::unseen`]).

use glam::Vec3;

use super::Camera;

/// The image of an axis-aligned box wholly in front of the lens ([`Camera::box_image`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxImage {
    /// Bounding rectangle of its image through the lens centre: x0, y0, x1, y1 in pixels.
    pub sharp: [f32; 4],
    /// Nearest depth along the view axis of its corners.
    pub near: f32,
    /// Farthest depth along the view axis of its corners.
    pub far: f32,
}

impl Camera {
    /// The image of the box `lo`..`hi`; `None` when part of it is not in front of the lens
    /// (behind the camera or around it), whose image has no bound.
    pub fn box_image(&self, lo: Vec3, hi: Vec3) -> Option<BoxImage> {
        let mut sharp = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        let (mut near, mut far) = (f32::INFINITY, 0.0f32);
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            // `project` refuses points not in front of the lens; a NaN comes out as one.
            let p = self.project(corner).filter(|p| p.is_finite())?;
            let depth = (corner - self.eye).dot(self.forward);
            (near, far) = (near.min(depth), far.max(depth));
            sharp = [
                sharp[0].min(p.x),
                sharp[1].min(p.y),
                sharp[2].max(p.x),
                sharp[3].max(p.y),
            ];
        }
        Some(BoxImage { sharp, near, far })
    }
}

impl BoxImage {
    /// Area of the sharp image's rectangle, square pixels.
    pub fn sharp_area(&self) -> f32 {
        (self.sharp[2] - self.sharp[0]) * (self.sharp[3] - self.sharp[1])
    }

    /// The largest CoC (pixels) of a point of the box: the CoC grows monotonically away from
    /// the plane in focus on either side, so it is largest at one end of the depth range.
    pub fn max_coc(&self, camera: &Camera) -> f32 {
        camera.coc_px(self.near).max(camera.coc_px(self.far))
    }

    /// The smallest CoC (pixels) of a point of the box: 0 when the plane in focus crosses its
    /// depth range, else the CoC at the end nearer to it.
    pub fn min_coc(&self, camera: &Camera) -> f32 {
        let focus = camera.focus_distance();
        if self.near <= focus && focus <= self.far {
            0.0
        } else {
            camera.coc_px(self.near).min(camera.coc_px(self.far))
        }
    }

    /// The film rectangle its light can reach through any lens position (a point moves at most
    /// half its CoC from its sharp image), grown by `margin` pixels more (a pixel filter's
    /// reach); `None` if not finite.
    pub fn reach(&self, camera: &Camera, margin: f32) -> Option<[f32; 4]> {
        self.grown(0.5 * self.max_coc(camera) + margin)
    }

    /// The sharp image's rectangle grown by `by` pixels on every side; `None` if not finite.
    pub fn grown(&self, by: f32) -> Option<[f32; 4]> {
        let [x0, y0, x1, y1] = self.sharp;
        let rect = [x0 - by, y0 - by, x1 + by, y1 + by];
        rect.iter().all(|v| v.is_finite()).then_some(rect)
    }
}

/// A `size` x `size` camera at the origin looking along +z (30 degrees), aperture radius 0.2,
/// focused at 5: what the footprint tests (here and in the renderer) look through.
#[cfg(test)]
pub(crate) fn test_camera(size: u32) -> Camera {
    use crate::camera::{ApertureShape, CameraSpec, Focus, LensSpec};
    CameraSpec {
        eye: Vec3::ZERO,
        look_at: Vec3::Z,
        up: Vec3::Y,
        vfov_deg: 30.0,
        width: size,
        height: size,
        lens: LensSpec::Aperture { radius: 0.2 },
        focus: Focus::Distance(5.0),
        aperture: ApertureShape::default(),
        real_lens: None,
    }
    .build(|_| None)
    .unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        test_camera(100)
    }

    #[test]
    fn blur_ranges_follow_the_plane_in_focus() {
        let c = camera();
        let across = c.box_image(Vec3::new(-0.1, -0.1, 4.0), Vec3::new(0.1, 0.1, 6.0));
        let across = across.unwrap();
        assert_eq!(across.min_coc(&c), 0.0);
        assert_eq!(across.max_coc(&c), c.coc_px(4.0).max(c.coc_px(6.0)));
        let behind = c
            .box_image(Vec3::new(-0.1, -0.1, 8.0), Vec3::new(0.1, 0.1, 9.0))
            .unwrap();
        assert_eq!(behind.min_coc(&c), c.coc_px(8.0));
        assert_eq!(behind.max_coc(&c), c.coc_px(9.0));
        // The sharp image of a box on the axis straddles the image centre.
        assert!(behind.sharp[0] < 50.0 && behind.sharp[2] > 50.0);
        let r = behind.reach(&c, 1.5).unwrap();
        assert!((behind.sharp[0] - r[0] - (0.5 * c.coc_px(9.0) + 1.5)).abs() < 1e-4);
        // A box around the eye has no image.
        assert!(c.box_image(Vec3::splat(-1.0), Vec3::splat(1.0)).is_none());
    }
}
