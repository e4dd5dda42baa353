//! A hillshade of a scenario's terrain about the site, lit by the scenario's sun with cast
//! shadows, as a PNG (the figure in docs/terrain.md). Each pixel: the surface point under
//! its centre, `max(0, n . s)` (Lambert) times 0 if a ray toward the sun meets the ground
//! within 3 km, plus a little ambient so shadows keep their shapes.
//!
//! `cargo run --release -p oils-lab --example terrain_hillshade -- pinpoint 1000 640 docs/img/pinpoint-detail-hillshade.png`
//! (scenario name or file, side of the square in m, pixels per side, output).

use oils_emulator::run_config::load_scenario;
use oils_emulator::world::sun::Sun;
use oils_emulator::world::terrain::{build, SiteFrame};
use plotters::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scenario, side_m, px, out] = args.as_slice() else {
        return Err("usage: terrain_hillshade SCENARIO SIDE_M PIXELS OUT.png".into());
    };
    let (side_m, px): (f64, u32) = (side_m.parse()?, px.parse()?);
    let s = load_scenario(scenario)?;
    s.validate()?;
    let site = SiteFrame::from_deg(s.site.latitude_deg, s.site.longitude_deg, s.moon.radius_m);
    let t0 = std::time::Instant::now();
    let terrain = build(&s.terrain, &site)?;
    let built = t0.elapsed();
    let sun = Sun::new(&s.sun, &site)?;
    let sun_site = sun.sun_dir_site(0);
    let (az, el) = sun.azimuth_elevation_deg(0);
    let root = BitMapBackend::new(out, (px, px)).into_drawing_area();
    let step = side_m / px as f64;
    for j in 0..px {
        for i in 0..px {
            let e = -0.5 * side_m + (i as f64 + 0.5) * step;
            let n = 0.5 * side_m - (j as f64 + 0.5) * step;
            let nrm = terrain.normal_site(e, n);
            let lambert = nrm.dot(&sun_site).max(0.0);
            let p = terrain.surface_point_site(e, n) + nrm * 0.02;
            let lit = lambert > 0.0 && terrain.ray_cast(&p, &sun_site, 3000.0).is_none();
            // Flat ground mid-grey whatever the sun's elevation; slopes facing it brighter.
            let flat = el.to_radians().sin().max(0.05);
            let v = 0.06 + if lit { 0.5 * lambert / flat } else { 0.0 };
            let g = (255.0 * v.clamp(0.0, 1.0)) as u8;
            root.draw_pixel((i as i32, j as i32), &RGBColor(g, g, g))?;
        }
    }
    root.present()?;
    println!(
        "{out}: {side_m} m square at {step:.3} m/px, sun azimuth {az:.2} deg elevation {el:.2} deg; terrain built in {built:.2?}, image in {:.2?}",
        t0.elapsed() - built
    );
    Ok(())
}
