//! The preview technique: one ray per pixel sample, shaded by the one
//! shading function with an eye light (a point light at the camera, no
//! attenuation) plus a little ambient, and no shadows. Fast, always
//! available, and the simplest end-to-end path through the whole system.
//! Where no surface is hit it shows the background every technique shows
//! (`texture::background_radiance`: the environment map or the colour).

use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::Result;
use chiaro_core::film::{Film, TilePixels, render_tiles};
use chiaro_core::geometry::Ray;
use chiaro_core::sampling::{pixel_rng, uniform2};
use chiaro_core::scene::{Attenuation, Facing, Light, Technique};
use chiaro_core::shading::texture::background_radiance;
use chiaro_core::shading::{LocalLighting, ShadingPoint, sanitize, shade_local};
use chiaro_core::technique::{Description, Feature};
use glam::{Vec2, Vec3};

/// Tile side in pixels.
const TILE: u32 = 32;
/// Pixels per camera-ray packet, across and down (the BVH's packet of
/// eight rays, `chiaro_core::accel::bvh::PACKET`).
const GROUP_W: u32 = 4;
const GROUP_H: u32 = 2;
const GROUP: usize = (GROUP_W * GROUP_H) as usize;

/// The preview technique, as the technique interface's [`Renderer`]:
/// eye-light shading, `settings.samples` jittered rays per pixel (one ray
/// through the pixel centre when `samples == 1`). The film's depth and
/// normal buffers come from the first sample of each pixel.
#[derive(Debug, Clone, Copy, Default)]
pub struct Preview;

impl Renderer for Preview {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)> {
        let settings = ctx.settings();
        let film = render_preview(ctx)?;
        let pixels = u64::from(settings.width) * u64::from(settings.height);
        Ok((film, ctx.stats(pixels * u64::from(settings.samples.max(1)))))
    }

    fn descriptions(&self) -> &'static [Description] {
        std::slice::from_ref(&DESCRIPTION)
    }
}

/// The preview technique, described.
pub const DESCRIPTION: Description = Description {
    technique: Technique::Preview,
    title: "preview",
    method: "ray cast, eye-light shading, no shadows: the fastest look",
    shows: "surfaces, textures, normal maps and highlights under an eye light; the background",
    cannot_show: &[
        (
            Feature::Lights,
            "the scene's lights and shadows: preview lights every surface with an eye light",
        ),
        (
            Feature::Mirrors,
            "mirror reflections: mirrors show their own colour",
        ),
        (
            Feature::Transparency,
            "transparency and refraction: drawn opaque",
        ),
        (Feature::EnvironmentLight, "light from the environment map"),
        (Feature::DepthCue, "depth cueing"),
    ],
};

fn render_preview(ctx: &RenderContext<'_>) -> Result<Film> {
    let (scene, settings, progress) = (ctx.scene(), ctx.settings(), ctx.progress());
    progress.begin("prepare", 1);
    let prepared = ctx.analytic();
    let accel = ctx.analytic_accel();
    progress.advance(1);
    let cam = ctx.camera();
    let eye_light = [
        Light::Point {
            position: cam.eye,
            color: Vec3::ONE,
            intensity: 1.0,
            attenuation: Attenuation::None,
        },
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.2,
        },
    ];
    let lighting = LocalLighting {
        lights: &eye_light,
        area_samples: 1,
        ambient: true,
        group: None,
        share: chiaro_core::shading::SampleShare::WHOLE,
    };
    let (w, h) = (settings.width, settings.height);
    let pixel_rays = cam.pixel_rays(w, h);
    let spp = settings.samples.max(1);
    render_tiles(
        w,
        h,
        settings.crop_rect(),
        TILE,
        "preview",
        progress,
        |rect| {
            let mut tile = TilePixels::new(rect);
            // Pixels in groups of GROUP_W x GROUP_H; each sample's rays of
            // a group are traced together (`intersect_camera_packet`, the
            // same hits as one at a time).
            for gy in (0..rect.height).step_by(GROUP_H as usize) {
                for gx in (0..rect.width).step_by(GROUP_W as usize) {
                    let mut pixels = [(0u32, 0u32); GROUP];
                    let mut n = 0;
                    for ty in gy..(gy + GROUP_H).min(rect.height) {
                        for tx in gx..(gx + GROUP_W).min(rect.width) {
                            pixels[n] = (tx, ty);
                            n += 1;
                        }
                    }
                    let mut sums = [Vec3::ZERO; GROUP];
                    let mut rays = [Ray::new(cam.eye, Vec3::Z); GROUP];
                    let mut hits = [None; GROUP];
                    for s in 0..spp {
                        for (ray, &(tx, ty)) in rays.iter_mut().zip(&pixels[..n]) {
                            let (px, py) = (rect.x + tx, rect.y + ty);
                            let offset = if spp == 1 {
                                Vec2::splat(0.5)
                            } else {
                                let mut rng = pixel_rng(settings.seed, px, py, s);
                                uniform2(&mut rng)
                            };
                            *ray = pixel_rays.ray(px as f32 + offset.x, py as f32 + offset.y);
                        }
                        accel.intersect_camera_packet(&rays[..n], &mut hits[..n]);
                        for k in 0..n {
                            let (ray, (tx, ty)) = (&rays[k], pixels[k]);
                            let dir = ray.dir;
                            let Some(hit) = hits[k] else {
                                sums[k] += background_radiance(scene, dir);
                                continue;
                            };
                            // The surface layer at the base level of textures.
                            let ss = prepared.shading_surface(ray, &hit, None);
                            let surf = ss.hit;
                            let wo = -dir;
                            // Face the viewer: the eye light lights whatever side we see.
                            let (n, ng) = if surf.ng.dot(wo) < 0.0 {
                                (-ss.ns, -surf.ng)
                            } else {
                                (ss.ns, surf.ng)
                            };
                            let sp = ShadingPoint {
                                p: surf.p,
                                n,
                                ng,
                                wo,
                            };
                            // The sidedness rule: the back of a one-sided
                            // surface reflects nothing; emitters emit from
                            // their front unless two-sided.
                            let mut m = ss.material;
                            if ss.facing(wo) == Facing::BackBlack {
                                m = m.without_reflection();
                            }
                            if surf.ng.dot(wo) < 0.0
                                && !prepared.material(surf.material).emission_two_sided
                            {
                                m.emission = Vec3::ZERO;
                            }
                            sums[k] += shade_local(
                                &m,
                                &sp,
                                &lighting,
                                |_, _| Vec2::splat(0.5),
                                |_, _| Vec3::ONE,
                            );
                            if s == 0 {
                                let i = (ty * rect.width + tx) as usize;
                                tile.depth[i] = hit.t * dir.length();
                                tile.normal[i] = n;
                            }
                        }
                    }
                    for (&(tx, ty), sum) in pixels[..n].iter().zip(&sums) {
                        tile.color[(ty * rect.width + tx) as usize] = sanitize(*sum / spp as f32);
                    }
                }
            }
            tile
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::accel::Accelerator;
    use chiaro_core::accel::list::ListAccel;
    use chiaro_core::prepared::PreparedScene;
    use chiaro_core::progress::NoProgress;
    use chiaro_core::scene::Scene;

    fn sphere_scene() -> Scene {
        let mut s = chiaro_testkit::scenes::white_sphere();
        s.render.width = 32;
        s.render.height = 32;
        s
    }

    fn list(p: &PreparedScene<'_>) -> Box<dyn Accelerator> {
        Box::new(ListAccel::new(p))
    }

    /// The preview of `s` over the brute-force accelerator.
    fn render_with(s: &Scene) -> Result<Film> {
        let ctx = RenderContext::new(s, &s.render, &NoProgress)?.with_accelerator(&list);
        Preview.render(&ctx).map(|(film, _)| film)
    }

    #[test]
    fn eye_light_sphere_is_brightest_in_the_middle() {
        let s = sphere_scene();
        let film = render_with(&s).expect("renders");
        assert!(film.is_clean());
        let centre = film.get(16, 16).x;
        // Facing the eye light 5 units away with no attenuation:
        // Ip kd cos = 0.8, plus ambient 0.2 * 0.1 * 0.8.
        assert!((centre - (0.8 + 0.016)).abs() < 0.01, "{centre}");
        assert!(film.get(16, 4).x < centre);
        assert_eq!(film.get(0, 0), Vec3::ZERO, "background");
        assert!(film.depth[film.index(16, 16)] > 3.9 && film.depth[film.index(16, 16)] < 4.1);
    }

    #[test]
    fn same_image_for_any_thread_count() {
        let mut s = sphere_scene();
        s.render.samples = 4;
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let a = one.install(|| render_with(&s)).expect("renders");
        let b = render_with(&s).expect("renders");
        assert_eq!(a, b);
    }
}
