//! Direct light from point, spot and directional lights on radiosity
//! elements: the "first unshot gather" that turns them into emission
//! before a solver runs (their radiance cannot be meshed into elements).

use crate::formfactor::sub_centroids;
use crate::mesh::Element;
use crate::ray_cast::Visibility;
use chiaro_core::geometry::Ray;
use chiaro_core::scene::Light;
use chiaro_core::shading::sample_light;
use glam::{Vec2, Vec3};

/// Reflected radiance at an element from the point, spot and directional
/// lights (the "first unshot gather"): `rho * sum_l mean_x f_att Ip spot
/// cos_theta V`, over 4 points of the element, with shadow rays. This is
/// `rho / pi` times the irradiance `pi Ip f_att cos / d^2` of the
/// radiometric convention, so it equals what the local techniques and the path tracer
/// give for a Lambertian surface. Area and ambient lights give nothing here.
pub(crate) fn point_light_direct(e: &Element, lights: &[Light], vis: &Visibility<'_>) -> Vec3 {
    if e.rho == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let mut xs = [Vec3::ZERO; 64];
    let nx = sub_centroids(&e.p, 2, &mut xs);
    let mut sum = Vec3::ZERO;
    for light in lights {
        if matches!(light, Light::Ambient { .. } | Light::Area { .. }) {
            continue;
        }
        for &x in &xs[..nx] {
            let Some(s) = sample_light(light, x, Vec2::splat(0.5)) else {
                continue;
            };
            let cos = s.wi.dot(e.n);
            if cos <= 0.0 {
                continue;
            }
            let o = x + e.n * vis.eps;
            let target = if s.distance.is_finite() {
                s.point
            } else {
                x + s.wi * 1.0e6
            };
            if vis.accel.occluded(&Ray::segment(o, target)) {
                continue;
            }
            sum += s.intensity * cos;
        }
    }
    e.rho * sum / nx as f32
}
