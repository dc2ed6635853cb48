//! The lenses a camera can hold, as one type: [`CameraLens`] forwards the [`Lens`] seam to the
//! thin lens or a real one.

use glam::{Vec2, Vec3};

use super::Camera;
use super::aperture::LensFilter;
use super::lens::{Landing, Lens, Reprojection, ThinLens};
use super::real_lens::RealLens;
use crate::embree::{LANES, Ray};

/// The lenses a camera can hold. An enum rather than a trait object so that
/// [`Lens::rays16`] stays one inlined, monomorphic loop per packet.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum CameraLens {
    /// An ideal thin lens.
    Thin(ThinLens),
    /// A lens prescription traced element by element.
    Real(Box<RealLens>),
}

/// Calls `$call` on the lens inside a [`CameraLens`], whichever it is.
macro_rules! dispatch {
    ($lens:expr, $l:ident => $call:expr) => {
        match $lens {
            CameraLens::Thin($l) => $call,
            CameraLens::Real($l) => $call,
        }
    };
}

impl Lens for CameraLens {
    #[inline]
    fn lens_point(&self, u: Vec2) -> Vec2 {
        dispatch!(self, l => l.lens_point(u))
    }

    #[inline]
    fn lens_points16(&self, u: &[f32; LANES], v: &[f32; LANES]) -> ([f32; LANES], [f32; LANES]) {
        dispatch!(self, l => l.lens_points16(u, v))
    }

    #[inline]
    fn ray(&self, camera: &Camera, px: f32, py: f32, lens: Vec2) -> (Ray, f32) {
        dispatch!(self, l => l.ray(camera, px, py, lens))
    }

    #[inline]
    fn rays16(
        &self,
        camera: &Camera,
        film: (&[f32; LANES], &[f32; LANES]),
        lens: (&[f32; LANES], &[f32; LANES]),
        origin: &mut [[f32; LANES]; 3],
        dir: &mut [[f32; LANES]; 3],
        weight: &mut [f32; LANES],
    ) {
        dispatch!(self, l => l.rays16(camera, film, lens, origin, dir, weight))
    }

    #[inline]
    fn pinhole_ray(&self, camera: &Camera, px: f32, py: f32) -> Ray {
        dispatch!(self, l => l.pinhole_ray(camera, px, py))
    }

    fn project(&self, camera: &Camera, p: Vec3) -> Option<Vec2> {
        dispatch!(self, l => l.project(camera, p))
    }

    #[inline]
    fn focus_point(&self, camera: &Camera, px: f32, py: f32) -> Vec3 {
        dispatch!(self, l => l.focus_point(camera, px, py))
    }

    fn entry_point(&self, u: Vec2) -> Vec2 {
        dispatch!(self, l => l.entry_point(u))
    }

    fn entry_origin(&self, camera: &Camera, entry: Vec2) -> Vec3 {
        dispatch!(self, l => l.entry_origin(camera, entry))
    }

    fn film_point(&self, camera: &Camera, entry: Vec2, dir: Vec3) -> Option<Landing> {
        dispatch!(self, l => l.film_point(camera, entry, dir))
    }

    fn entry_yield(&self, camera: &Camera, from: Vec3) -> f32 {
        dispatch!(self, l => l.entry_yield(camera, from))
    }

    fn distorts(&self) -> bool {
        dispatch!(self, l => l.distorts())
    }

    #[inline]
    fn weight(&self, filter: LensFilter, lens: Vec2) -> f32 {
        dispatch!(self, l => l.weight(filter, lens))
    }

    #[inline]
    fn coc_px(&self, camera: &Camera, depth: f32) -> f32 {
        dispatch!(self, l => l.coc_px(camera, depth))
    }

    #[inline]
    fn coc_px_at(&self, camera: &Camera, depth: f32, film: Vec2) -> f32 {
        dispatch!(self, l => l.coc_px_at(camera, depth, film))
    }

    fn reprojection(&self, camera: &Camera) -> Option<Reprojection> {
        dispatch!(self, l => l.reprojection(camera))
    }

    fn focus_distance(&self) -> f32 {
        dispatch!(self, l => l.focus_distance())
    }

    fn aperture_radius(&self) -> f32 {
        dispatch!(self, l => l.aperture_radius())
    }
}
