//! Renderers: a frame's I/F per pixel from the ground, the camera's pose and the sun.
//!
//! * [`Renderer::Exact`], the oracle: per pixel, the ray through the pixel's centre is
//!   cast on the ground ([`Ground::ray_cast_mcmf`], exact on the sphere, the terrain's
//!   refined march otherwise), shaded with the lunar-Lambert I/F at the hit, and a
//!   second ray from the hit towards the sun decides the cast shadow. About 2-3 us a
//!   pixel: seconds for a 1024^2 frame.
//! * [`Renderer::Fast`]: on a terrain, the heightfield is sampled on a lattice in map
//!   coordinates whose spacing is the pixel footprint at the nearest visible point
//!   (found by 81 exact probe rays), each node shaded once (the same I/F as the oracle,
//!   the cast shadow from the [`ShadowMap`]), projected, and the lattice's triangles
//!   rasterised with a depth buffer (I/F linear across each triangle), two rows of
//!   nodes at a time. A pixel no triangle covers (sky, beyond the lattice, behind the
//!   camera) falls back to the oracle's ray. On the bare sphere it is the oracle (an
//!   exact ray-sphere intersection costs tens of ns).
//!
//! Pixels that see the sky are 0, or infinite (saturated) within the sun's disk.

use super::optics::Pinhole;
use super::photometry::iof_at;
use super::shadow::ShadowMap;
use super::SUN_ANGULAR_RADIUS_RAD;
use crate::plant::ground::Ground;
use crate::world::terrain::{SiteFrame, Terrain};
use nalgebra::{Matrix3, Vector3};

/// Longest camera ray, m (the horizon from 5 km up is 132 km away).
const MAX_VIEW_RANGE_M: f64 = 300_000.0;
/// Longest shadow ray, m.
const MAX_SHADOW_RANGE_M: f64 = 50_000.0;
/// A shadow ray starts this far above the hit along the normal, m (the hit lies within
/// the ray cast's 1e-6 m tolerance below the surface).
const SHADOW_RAY_LIFT_M: f64 = 1e-3;
/// Probe rays per side of the image (the fast renderer's footprint).
const PROBES: u32 = 9;
/// Lattice spacing in pixel footprints at the nearest visible point.
const NODE_SPACING_PX: f64 = 1.0;
/// Nodes projecting further than this outside the image are not shaded, pixels.
const OFF_IMAGE_PX: f64 = 4.0;
/// Most lattice nodes a frame samples (beyond: the spacing grows).
const MAX_NODES: f64 = 4.0e6;

/// Which renderer draws the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Renderer {
    /// Lattice rasterisation with the shadow map; exact rays where it has nothing.
    Fast,
    /// Two exact ray casts a pixel: the oracle.
    Exact,
}

/// A sensor's pose at one instant, Moon-fixed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Optical centre, `mcmf`, m.
    pub origin_mcmf: Vector3<f64>,
    /// Columns: the sensor's x, y, z (boresight) axes in `mcmf`.
    pub mcmf_from_sensor: Matrix3<f64>,
}

/// Surface and sun.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shading<'a> {
    pub albedo: f64,
    pub floor_iof: f64,
    /// Unit, towards the sun.
    pub sun_mcmf: Vector3<f64>,
    /// Usable for this frame (same ground, sun within tolerance), if any.
    pub shadow: Option<&'a ShadowMap>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Vertex {
    u: f32,
    v: f32,
    z: f32,
    iof: f32,
    ok: bool,
}

/// Buffers a frame needs, allocated with the camera.
#[derive(Debug, Clone)]
pub(crate) struct Scratch {
    depth: Vec<f32>,
    sample: Vec<f32>,
    rows: [Vec<Vertex>; 2],
    /// Sky pixels of the last pose rendered.
    pub sky_pixels: u32,
    /// Lattice nodes of the last fast frame (for benches and docs).
    pub nodes: usize,
    /// Pixels of the last fast frame that fell back to an exact ray.
    pub fallback_pixels: u32,
}

impl Scratch {
    pub fn new(pixels: usize, row_nodes: usize) -> Self {
        Self {
            depth: vec![f32::INFINITY; pixels],
            sample: vec![0.0; pixels],
            rows: [
                vec![Vertex::default(); row_nodes],
                vec![Vertex::default(); row_nodes],
            ],
            sky_pixels: 0,
            nodes: 0,
            fallback_pixels: 0,
        }
    }
}

/// Renders one pose into `iof` (or, with `mean = Some((k, n))`, adds its share `1/n`
/// of the mean, clearing on `k = 0`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_pose(
    renderer: Renderer,
    ground: &Ground,
    cam: &Pinhole,
    pose: &Pose,
    shading: &Shading<'_>,
    scratch: &mut Scratch,
    iof: &mut [f32],
    mean: Option<(u32, u32)>,
) {
    let mut sample = std::mem::take(&mut scratch.sample);
    let target: &mut [f32] = if mean.is_some() { &mut sample } else { iof };
    match (renderer, ground) {
        (Renderer::Fast, Ground::Terrain { terrain, site, .. }) => {
            render_fast(terrain, site, ground, cam, pose, shading, scratch, target)
        }
        _ => render_exact(ground, cam, pose, shading, scratch, target),
    }
    if let Some((k, n)) = mean {
        let w = 1.0 / n as f32;
        for (acc, s) in iof.iter_mut().zip(&sample) {
            let prev = if k == 0 { 0.0 } else { *acc };
            *acc = prev + w * s;
        }
    }
    scratch.sample = sample;
}

/// The exact renderer: two ray casts a pixel.
fn render_exact(
    ground: &Ground,
    cam: &Pinhole,
    pose: &Pose,
    shading: &Shading<'_>,
    scratch: &mut Scratch,
    out: &mut [f32],
) {
    let mut sky = 0;
    for j in 0..cam.height {
        for i in 0..cam.width {
            let d = pose.mcmf_from_sensor * cam.pixel_ray(i, j);
            let (value, is_sky) = exact_pixel(ground, &pose.origin_mcmf, &d, shading);
            sky += is_sky as u32;
            out[(j * cam.width + i) as usize] = value;
        }
    }
    scratch.sky_pixels = sky;
}

/// One pixel by exact rays, `mcmf`: its I/F and whether it saw the sky.
fn exact_pixel(
    ground: &Ground,
    origin: &Vector3<f64>,
    dir: &Vector3<f64>,
    shading: &Shading<'_>,
) -> (f32, bool) {
    let s = &shading.sun_mcmf;
    match ground.ray_cast_mcmf(origin, dir, MAX_VIEW_RANGE_M) {
        None => (sky_value(dir, s), true),
        Some(hit) => {
            let n = hit.normal_mcmf;
            if n.dot(s) <= 0.0 {
                return (shading.floor_iof as f32, false);
            }
            let lift = hit.point_mcmf + n * SHADOW_RAY_LIFT_M;
            if ground.ray_cast_mcmf(&lift, s, MAX_SHADOW_RANGE_M).is_some() {
                return (shading.floor_iof as f32, false);
            }
            let v = dir.normalize();
            (
                (iof_at(shading.albedo, &n, &v, s) + shading.floor_iof) as f32,
                false,
            )
        }
    }
}

/// The sky along unit-able `dir`: the sun's disk saturates, the rest is black.
fn sky_value(dir: &Vector3<f64>, sun: &Vector3<f64>) -> f32 {
    if dir.normalize().dot(sun) >= SUN_ANGULAR_RADIUS_RAD.cos() {
        f32::INFINITY
    } else {
        0.0
    }
}

/// I/F of a terrain point, site frame: `p` at map `(e, n)` with unit normal `nrm`, seen
/// along unit `view`, the cast shadow from the map where it covers the point and an
/// exact shadow ray elsewhere.
#[allow(clippy::too_many_arguments)]
#[inline]
fn shade_site(
    terrain: &Terrain,
    shading: &Shading<'_>,
    sun_site: &Vector3<f64>,
    e: f64,
    n: f64,
    p: &Vector3<f64>,
    nrm: &Vector3<f64>,
    view: &Vector3<f64>,
) -> f64 {
    if nrm.dot(sun_site) <= 0.0 || nrm.dot(view) >= 0.0 {
        return shading.floor_iof;
    }
    let lit = match shading.shadow.and_then(|m| m.margin_m(e, n, p)) {
        Some(margin) => margin >= 0.0,
        None => terrain
            .ray_cast(&(p + nrm * SHADOW_RAY_LIFT_M), sun_site, MAX_SHADOW_RANGE_M)
            .is_none(),
    };
    if lit {
        iof_at(shading.albedo, nrm, view, sun_site) + shading.floor_iof
    } else {
        shading.floor_iof
    }
}

/// [`crate::world::terrain::MapProjection::site_of_map`] without its `hypot` and `cos`:
/// within 0.01 rad of the site (17 km) the series of `sin(theta)/s` and `cos(theta)` in
/// `theta^2` (to `theta^6`, below 1e-16 relative); beyond, the projection itself.
#[inline]
pub(crate) fn site_point(
    map: &crate::world::terrain::MapProjection,
    e: f64,
    n: f64,
    h: f64,
) -> Vector3<f64> {
    if map.is_flat() {
        return Vector3::new(e, n, h);
    }
    let r0 = map.radius_m;
    let t2 = (e * e + n * n) / (r0 * r0);
    if t2 >= 1e-4 {
        return map.site_of_map(e, n, h);
    }
    let f = (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0))) / r0;
    let c = 1.0 - t2 / 2.0 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0));
    let rho = r0 + h;
    // rho c - R = h c - R (1 - c), the latter small: no cancellation.
    let one_minus_c = t2 / 2.0 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0));
    Vector3::new(rho * f * e, rho * f * n, h * c - r0 * one_minus_c)
}

/// The fast renderer over a terrain (module documentation).
#[allow(clippy::too_many_arguments)]
fn render_fast(
    terrain: &Terrain,
    site: &SiteFrame,
    ground: &Ground,
    cam: &Pinhole,
    pose: &Pose,
    shading: &Shading<'_>,
    scratch: &mut Scratch,
    out: &mut [f32],
) {
    let rot_site_from_mcmf = site.rot_site_from_mcmf();
    let o = site.site_from_mcmf(&pose.origin_mcmf);
    let site_from_cam = rot_site_from_mcmf * pose.mcmf_from_sensor;
    let cam_from_site = site_from_cam.transpose();
    let sun_site = site.site_dir_from_mcmf(&shading.sun_mcmf);
    scratch.depth.fill(f32::INFINITY);
    out.fill(0.0);

    // Probe: the visible ground's map box and the nearest range.
    let (mut e_lo, mut e_hi, mut n_lo, mut n_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut t_min = f64::MAX;
    for pj in 0..PROBES {
        for pi in 0..PROBES {
            let u = cam.width as f64 * pi as f64 / (PROBES - 1) as f64;
            let v = cam.height as f64 * pj as f64 / (PROBES - 1) as f64;
            let d = site_from_cam * cam.ray(u, v);
            if let Some(hit) = terrain.ray_cast(&o, &d, MAX_VIEW_RANGE_M) {
                let (e, n) = terrain.map_of_site(&hit.point_site);
                e_lo = e_lo.min(e);
                e_hi = e_hi.max(e);
                n_lo = n_lo.min(n);
                n_hi = n_hi.max(n);
                t_min = t_min.min(hit.range_m);
            }
        }
    }
    let mut nodes = 0usize;
    if t_min < f64::MAX {
        // Pad the box: hills between probes may show ground just outside it.
        let pad = 0.05 * (e_hi - e_lo).max(n_hi - n_lo) + 1.0;
        let (e_lo, e_hi, n_lo, n_hi) = (e_lo - pad, e_hi + pad, n_lo - pad, n_hi + pad);
        let row_cap = scratch.rows[0].len();
        let mut spacing = (NODE_SPACING_PX * t_min * cam.pixel_angle_rad()).max(1e-4);
        let count = |s: f64| {
            (
                ((e_hi - e_lo) / s).ceil() + 1.0,
                ((n_hi - n_lo) / s).ceil() + 1.0,
            )
        };
        let (nx, ny) = count(spacing);
        if nx * ny > MAX_NODES {
            spacing *= (nx * ny / MAX_NODES).sqrt();
        }
        let (nx, _) = count(spacing);
        if nx > row_cap as f64 {
            spacing *= nx / (row_cap as f64 - 1.0);
        }
        let (nx, ny) = count(spacing);
        let (nx, ny) = (nx as usize, ny as usize);
        nodes = nx * ny;
        let map = terrain.map();
        let w_px = cam.width as f64 + OFF_IMAGE_PX;
        let h_px = cam.height as f64 + OFF_IMAGE_PX;
        let [mut prev, mut cur] = std::mem::take(&mut scratch.rows);
        for j in 0..ny {
            let n = n_lo + spacing * j as f64;
            for (i, vert) in cur.iter_mut().take(nx).enumerate() {
                let e = e_lo + spacing * i as f64;
                // One sample for the node's height and, on the image, its normal.
                let sample = terrain.sample(e, n);
                let p = site_point(map, e, n, sample.h_m);
                let rel = p - o;
                let pc = cam_from_site * rel;
                *vert = match cam.project(&pc) {
                    // Off the image by more than a triangle's size (at most about a
                    // pixel): no pixel centre of its triangles is in the frame.
                    Some((u, v))
                        if u < -OFF_IMAGE_PX || v < -OFF_IMAGE_PX || u > w_px || v > h_px =>
                    {
                        Vertex {
                            u: u as f32,
                            v: v as f32,
                            z: pc.z as f32,
                            iof: 0.0,
                            ok: true,
                        }
                    }
                    Some((u, v)) => {
                        // The terrain's own normal, as the oracle's hit has it.
                        let nrm = terrain.normal_from_sample(e, n, &sample);
                        let view = rel / rel.norm();
                        let iof = shade_site(terrain, shading, &sun_site, e, n, &p, &nrm, &view);
                        Vertex {
                            u: u as f32,
                            v: v as f32,
                            z: pc.z as f32,
                            iof: iof as f32,
                            ok: true,
                        }
                    }
                    None => Vertex::default(),
                };
            }
            if j > 0 {
                for i in 0..nx - 1 {
                    let (a, b, c, d) = (prev[i], prev[i + 1], cur[i + 1], cur[i]);
                    if a.ok && b.ok && c.ok {
                        raster_triangle(cam, &mut scratch.depth, out, &a, &b, &c);
                    }
                    if a.ok && c.ok && d.ok {
                        raster_triangle(cam, &mut scratch.depth, out, &a, &c, &d);
                    }
                }
            }
            std::mem::swap(&mut prev, &mut cur);
        }
        scratch.rows = [prev, cur];
    }
    scratch.nodes = nodes;

    // Whatever no triangle covered: the exact ray.
    let (mut sky, mut fallback) = (0u32, 0u32);
    for j in 0..cam.height {
        for i in 0..cam.width {
            let k = (j * cam.width + i) as usize;
            if scratch.depth[k].is_finite() {
                continue;
            }
            fallback += 1;
            let d = pose.mcmf_from_sensor * cam.pixel_ray(i, j);
            let (value, is_sky) = exact_pixel(ground, &pose.origin_mcmf, &d, shading);
            sky += is_sky as u32;
            out[k] = value;
        }
    }
    scratch.sky_pixels = sky;
    scratch.fallback_pixels = fallback;
}

/// `ceil(x)` for a finite `x >= 0`.
#[inline]
fn ceil_nonneg(x: f32) -> u32 {
    let t = x as u32;
    t + ((t as f32) < x) as u32
}

/// Fills the pixel centres inside triangle `abc` that are nearer than the depth buffer,
/// with the I/F interpolated linearly on the image.
#[inline]
fn raster_triangle(
    cam: &Pinhole,
    depth: &mut [f32],
    out: &mut [f32],
    a: &Vertex,
    b: &Vertex,
    c: &Vertex,
) {
    let area = (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
    if area.abs() < 1e-12 || !area.is_finite() {
        return;
    }
    let inv = 1.0 / area;
    let (w, h) = (cam.width as f32, cam.height as f32);
    let u_lo = a.u.min(b.u).min(c.u);
    let u_hi = a.u.max(b.u).max(c.u);
    let v_lo = a.v.min(b.v).min(c.v);
    let v_hi = a.v.max(b.v).max(c.v);
    // Pixel centres i + 0.5 within [u_lo, u_hi] (integer casts: `floor`/`ceil` are
    // library calls on the baseline x86-64 target).
    if u_hi < 0.5 || v_hi < 0.5 || u_lo > w - 0.5 || v_lo > h - 0.5 {
        return;
    }
    let i0 = ceil_nonneg((u_lo - 0.5).max(0.0));
    let i1 = ((u_hi - 0.5) as u32).min(cam.width - 1);
    let j0 = ceil_nonneg((v_lo - 0.5).max(0.0));
    let j1 = ((v_hi - 0.5) as u32).min(cam.height - 1);
    if i0 > i1 || j0 > j1 {
        return;
    }
    const EPS: f32 = -1e-5;
    for j in j0..=j1 {
        let y = j as f32 + 0.5;
        for i in i0..=i1 {
            let x = i as f32 + 0.5;
            let wa = ((b.u - x) * (c.v - y) - (b.v - y) * (c.u - x)) * inv;
            let wb = ((c.u - x) * (a.v - y) - (c.v - y) * (a.u - x)) * inv;
            let wc = 1.0 - wa - wb;
            if wa < EPS || wb < EPS || wc < EPS {
                continue;
            }
            let z = wa * a.z + wb * b.z + wc * c.z;
            let k = (j * cam.width + i) as usize;
            if z < depth[k] {
                depth[k] = z;
                out[k] = wa * a.iof + wb * b.iof + wc * c.iof;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::terrain::MapProjection;

    #[test]
    fn site_point_is_the_projection() {
        let map = MapProjection {
            radius_m: 1_737_400.0,
        };
        for (e, n, h) in [
            (0.0, 0.0, 3.0),
            (1500.0, -2500.0, -40.0),
            (-9000.0, 12_000.0, 800.0),
            (20_000.0, 5.0, 1.0),
        ] {
            let a = site_point(&map, e, n, h);
            let b = map.site_of_map(e, n, h);
            assert!((a - b).norm() < 1e-8, "{e},{n}: {}", (a - b).norm());
        }
    }
}
