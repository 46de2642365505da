//! The thin-lens camera and the crop window: ray generation, the raster
//! position of a ray, the inverse map (fused state spaces) and the
//! connection from a scene point, checked against each other and against
//! hand-computed cases.

use glam::{Mat4, Quat, Vec2, Vec3};
use mcmc_render::camera::Camera;
use mcmc_render::scene::{CameraDesc, FilmDesc, FovAxis};

fn film(full: (u32, u32), crop: (u32, u32, u32, u32)) -> FilmDesc {
    FilmDesc {
        width: crop.2,
        height: crop.3,
        full_width: full.0,
        full_height: full.1,
        crop_offset: (crop.0, crop.1),
        ..FilmDesc::default()
    }
}

fn desc(aperture: f32, focus: f32) -> CameraDesc {
    CameraDesc {
        // At (0.3, 0.5, 5), looking roughly down −z.
        to_world: Mat4::from_rotation_translation(
            Quat::from_rotation_y(std::f32::consts::PI + 0.1),
            Vec3::new(0.3, 0.5, 5.0),
        ),
        fov_deg: 45.0,
        fov_axis: FovAxis::X,
        aperture_radius: aperture,
        focus_distance: focus,
        ..CameraDesc::default()
    }
}

/// Numbers on a grid away from the unit square's edges.
fn grid() -> impl Iterator<Item = (f32, f32)> {
    (0..7).flat_map(|i| (0..7).map(move |j| ((i as f32 + 0.3) / 7.0, (j as f32 + 0.6) / 7.0)))
}

#[test]
fn lens_rays_land_where_they_were_generated_and_invert() {
    let cam = Camera::new(&desc(0.2, 4.0), &film((64, 48), (0, 0, 64, 48))).unwrap();
    assert!(cam.has_lens());
    for u in grid() {
        for raster in [
            Vec2::new(3.3, 7.1),
            Vec2::new(40.5, 30.2),
            Vec2::new(63.5, 0.5),
        ] {
            let ray = cam.generate_ray_lens(raster, u);
            let (r, cos) = cam.raster_of_ray(ray.o, ray.d).expect("on the image");
            assert!((r - raster).length() < 2e-3, "{r} vs {raster}");
            assert!(cos > 0.0 && cos <= 1.0);
            let (r2, u2) = cam.invert(ray.o, ray.d).expect("invertible");
            assert!((r2 - raster).length() < 2e-3);
            assert!(
                (u2.0 - u.0).abs() < 1e-4 && (u2.1 - u.1).abs() < 1e-4,
                "{u:?} {u2:?}"
            );
            // Every ray of a raster position passes through the same point
            // of the focus plane (the pinhole ray's).
            let centre = cam.generate_ray(raster);
            let axis = cam.generate_ray(Vec2::new(32.0, 24.0)).d;
            let p_focus = centre.o + centre.d * (4.0 / centre.d.dot(axis));
            let q = ray.o + ray.d * ((p_focus - ray.o).dot(axis) / ray.d.dot(axis));
            assert!((q - p_focus).length() < 1e-4, "{q} vs {p_focus}");
        }
    }
}

#[test]
fn a_connection_reaches_the_raster_position_of_the_ray_back() {
    let cam = Camera::new(&desc(0.2, 4.0), &film((64, 48), (0, 0, 64, 48))).unwrap();
    let p = Vec3::new(0.3, 0.2, -0.4);
    for u in grid() {
        let cs = cam.sample_wi_lens(p, u).expect("in view");
        // The connecting ray, traced from the lens, lands on that raster.
        let ray = cam.generate_ray_lens(cs.raster, u);
        assert!((ray.o - cs.origin).length() < 1e-5);
        assert!(ray.d.dot(-cs.wi) > 1.0 - 1e-5, "{} vs {}", ray.d, -cs.wi);
        // pdf = d² / cos, as for the pinhole.
        let (_, cos) = cam.raster_of_ray(cs.origin, -cs.wi).unwrap();
        assert!((cs.pdf - cs.dist * cs.dist / cos).abs() < 1e-4 * cs.pdf);
    }
}

#[test]
fn the_crop_window_is_part_of_the_full_frame() {
    let full = Camera::new(&desc(0.0, 1e4), &film((80, 60), (0, 0, 80, 60))).unwrap();
    let crop = Camera::new(&desc(0.0, 1e4), &film((80, 60), (10, 20, 30, 15))).unwrap();
    assert_eq!(crop.resolution(), (30, 15));
    for raster in [
        Vec2::new(0.5, 0.5),
        Vec2::new(29.9, 14.9),
        Vec2::new(12.3, 7.7),
    ] {
        let a = crop.generate_ray(raster);
        let b = full.generate_ray(raster + Vec2::new(10.0, 20.0));
        assert!((a.d - b.d).length() < 1e-6);
        assert!((crop.raster_of(a.d).unwrap().0 - raster).length() < 1e-3);
    }
    // Outside the window: not on the image.
    assert!(
        crop.raster_of(full.generate_ray(Vec2::new(5.0, 5.0)).d)
            .is_none()
    );
    // W_e is normalised over the window: its area on the plane z = 1 is
    // the window's share of the frame's, so the density of a direction is
    // larger by the frame/window pixel ratio.
    let d = full.generate_ray(Vec2::new(25.0, 27.0)).d;
    let ratio = crop.pdf_we(crop.lens_point((0.5, 0.5)), d).1
        / full.pdf_we(full.lens_point((0.5, 0.5)), d).1;
    assert!(
        (ratio - (80.0 * 60.0) / (30.0 * 15.0)).abs() < 1e-3,
        "{ratio}"
    );
}
