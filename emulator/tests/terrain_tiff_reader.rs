//! The GeoTIFF reader's refusals and its polar stereographic reading on small files this
//! test writes with the `tiff` crate's encoder (the GDAL-made files are checked by
//! `terrain_geotiff`, run from `tools/terrain-e2e.sh`). Each refusal is a typed error
//! that names the file.

use oils_emulator::world::terrain::geotiff::GeoDem;
use oils_emulator::world::terrain::TerrainError;
use std::path::{Path, PathBuf};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;

const R_M: f64 = 1_737_400.0;

enum Georef {
    TieScale,
    Transform([f64; 16]),
    Nothing,
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("oils-tiff-reader-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// An 8 x 6 float32 DEM, `h = 10 col + row`, with the given GeoKeys and georeference;
/// pixel (0, 0)'s corner at model (1000, 2000), 10 m pixels.
fn write(path: &Path, keys: &[u16], doubles: &[f64], georef: Georef) {
    let (w, h) = (8u32, 6u32);
    let data: Vec<f32> = (0..h)
        .flat_map(|r| (0..w).map(move |c| (10 * c + r) as f32))
        .collect();
    let file = std::fs::File::create(path).unwrap();
    let mut enc = TiffEncoder::new(file).unwrap();
    let mut img = enc.new_image::<colortype::Gray32Float>(w, h).unwrap();
    let d = img.encoder();
    match georef {
        Georef::TieScale => {
            d.write_tag(Tag::ModelPixelScaleTag, &[10.0f64, 10.0, 0.0][..])
                .unwrap();
            d.write_tag(
                Tag::ModelTiepointTag,
                &[0.0f64, 0.0, 0.0, 1000.0, 2000.0, 0.0][..],
            )
            .unwrap();
        }
        Georef::Transform(m) => d.write_tag(Tag::ModelTransformationTag, &m[..]).unwrap(),
        Georef::Nothing => {}
    }
    if !keys.is_empty() {
        d.write_tag(Tag::GeoKeyDirectoryTag, keys).unwrap();
    }
    if !doubles.is_empty() {
        d.write_tag(Tag::GeoDoubleParamsTag, doubles).unwrap();
    }
    img.write_data(&data).unwrap();
}

/// GeoKeys of a south polar stereographic map (variant A) on a sphere of `a`, `b`.
fn polar_keys(coord_trans: u16) -> (Vec<u16>, Vec<f64>) {
    let keys = vec![
        1,
        1,
        0,
        8, // header: version 1.1.0, 8 keys
        1024,
        0,
        1,
        1, // projected model
        1025,
        0,
        1,
        1, // PixelIsArea
        2057,
        34736,
        1,
        0, // semi-major axis
        2058,
        34736,
        1,
        1, // semi-minor axis
        3075,
        0,
        1,
        coord_trans,
        3081,
        34736,
        1,
        2, // natural origin latitude
        3095,
        34736,
        1,
        3, // straight vertical pole longitude
        3092,
        34736,
        1,
        4, // scale
    ];
    (keys, vec![R_M, R_M, -90.0, 0.0, 1.0])
}

fn open_err(path: &Path) -> TerrainError {
    let err = GeoDem::open(path).expect_err("refused");
    let msg = err.to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    err
}

#[test]
fn reads_a_polar_stereographic_file_with_its_georeference() {
    let path = scratch("polar.tif");
    let (keys, doubles) = polar_keys(15);
    write(&path, &keys, &doubles, Georef::TieScale);
    let dem = GeoDem::open(&path).unwrap();
    assert_eq!(dem.size(), (8, 6));
    // PixelIsArea: pixel (0, 0)'s centre is half a pixel in from the tie point.
    assert_eq!(dem.transform(), (1005.0, 1995.0, 10.0, 10.0));
    assert_eq!(dem.elevation_at_pixel(3.0, 2.0), Some(32.0));
    assert_eq!(dem.elevation_at_pixel(3.5, 2.25), Some(37.25));
    // Model (1040, 1970): 3.5 pixels right of and 2.5 below pixel (0, 0)'s centre.
    assert_eq!(dem.pixel_of_model(1040.0, 1970.0), (3.5, 2.5));
    // The south pole projects to the map origin.
    let (x, y) = dem.projection().forward(-90f64.to_radians(), 0.3).unwrap();
    assert!(x.abs() < 1e-9 && y.abs() < 1e-9);
}

#[test]
fn refuses_what_it_cannot_read_with_typed_errors() {
    let (keys, doubles) = polar_keys(15);

    let p = scratch("nogeoref.tif");
    write(&p, &keys, &doubles, Georef::Nothing);
    assert!(matches!(
        open_err(&p),
        TerrainError::MissingGeoreference { .. }
    ));

    let p = scratch("rotated.tif");
    let mut m = [0.0; 16];
    m[0] = 10.0;
    m[1] = 1.0; // shear: a rotated raster
    m[3] = 1000.0;
    m[5] = -10.0;
    m[7] = 2000.0;
    m[15] = 1.0;
    write(&p, &keys, &doubles, Georef::Transform(m));
    let e = open_err(&p);
    assert!(
        matches!(e, TerrainError::Unsupported { ref what, .. } if what.contains("rotated")),
        "{e}"
    );

    let p = scratch("transform.tif");
    m[1] = 0.0;
    write(&p, &keys, &doubles, Georef::Transform(m));
    let dem = GeoDem::open(&p).unwrap();
    assert_eq!(dem.transform(), (1005.0, 1995.0, 10.0, 10.0));

    let p = scratch("nokeys.tif");
    write(&p, &[], &[], Georef::TieScale);
    assert!(matches!(
        open_err(&p),
        TerrainError::MissingGeoreference { .. }
    ));

    let p = scratch("ellipsoid.tif");
    let mut d2 = doubles.clone();
    d2[1] = R_M - 1000.0;
    write(&p, &keys, &d2, Georef::TieScale);
    let e = open_err(&p);
    assert!(
        matches!(e, TerrainError::Unsupported { ref what, .. } if what.contains("sphere")),
        "{e}"
    );

    let p = scratch("mercator.tif");
    let (k7, d7) = polar_keys(7);
    write(&p, &k7, &d7, Georef::TieScale);
    let e = open_err(&p);
    assert!(
        matches!(e, TerrainError::Unsupported { ref what, .. } if what.contains("ProjCoordTrans 7")),
        "{e}"
    );

    let p = scratch("missing.tif");
    let _ = std::fs::remove_file(&p);
    assert!(matches!(open_err(&p), TerrainError::Io { .. }));

    let p = scratch("garbage.tif");
    std::fs::write(&p, b"II*\0 this is not a tiff").unwrap();
    assert!(matches!(open_err(&p), TerrainError::Tiff { .. }));
}
