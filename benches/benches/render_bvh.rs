//! BVH build time and ray throughput (closest hit and occlusion) of the
//! renderer's geometry layer, on Mitsuba's Cornell box and on a generated
//! sphere of about one million triangles.
//!
//! Run: `cargo bench -p mcmc-benches --bench render_bvh`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use mcmc_render::geometry::{GeoShape, Geometry, MeshData, Ray, Surface};
use mcmc_render::scene::Scene;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::collections::HashMap;
use std::hint::black_box;
use std::path::Path;

/// A UV sphere with `n` segments in longitude and `n/2`·2 rings: ≈ 2·n·(n/2) triangles.
fn tessellated_sphere(n: u32) -> MeshData {
    let rings = n / 2;
    let mut positions = Vec::new();
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..n {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / n as f32;
            positions.push(Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ));
        }
    }
    let mut indices = Vec::new();
    for i in 0..rings {
        for j in 0..n {
            let a = i * n + j;
            let b = i * n + (j + 1) % n;
            let c = a + n;
            let d = b + n;
            if i != 0 {
                indices.push([a, b, c]);
            }
            if i != rings - 1 {
                indices.push([b, d, c]);
            }
        }
    }
    MeshData {
        positions,
        normals: None,
        uvs: None,
        indices,
    }
}

/// Rays from random points inside a box towards uniform random directions.
fn random_rays(lo: Vec3, hi: Vec3, n: usize) -> Vec<Ray> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    let mut u = || (rng.next_u32() >> 8) as f32 / 16_777_216.0;
    (0..n)
        .map(|_| {
            let o = lo + (hi - lo) * Vec3::new(u(), u(), u());
            let z = 1.0 - 2.0 * u();
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * std::f32::consts::PI * u();
            Ray::new(o, Vec3::new(r * phi.cos(), r * phi.sin(), z))
        })
        .collect()
}

fn bench_rays(c: &mut Criterion, name: &str, geometry: &Geometry, rays: &[Ray]) {
    let mut g = c.benchmark_group(format!("rays/{name}"));
    g.sample_size(10);
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.bench_function("closest", |b| {
        b.iter(|| {
            let mut hits = 0u32;
            for r in rays {
                hits += u32::from(geometry.intersect(r).is_some());
            }
            black_box(hits)
        })
    });
    g.bench_function("occlusion", |b| {
        b.iter(|| {
            let mut blocked = 0u32;
            for r in rays {
                let mut r = *r;
                r.tmax = 0.5;
                blocked += u32::from(geometry.occluded(&r));
            }
            black_box(blocked)
        })
    });
    g.finish();
}

fn cornell(c: &mut Criterion) {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../mcmc-render/tests/scenes/cornell-box.xml");
    let scene = Scene::load(&path, &HashMap::new()).expect("cornell box loads");
    let shapes = scene.geometry.shapes.clone();
    let mut g = c.benchmark_group("bvh_build/cornell");
    g.sample_size(20);
    g.bench_function("build", |b| {
        b.iter(|| black_box(Geometry::build(shapes.clone())))
    });
    g.finish();
    let rays = random_rays(Vec3::splat(-0.99), Vec3::splat(0.99), 100_000);
    bench_rays(c, "cornell", &scene.geometry, &rays);
}

fn million(c: &mut Criterion) {
    let mesh = tessellated_sphere(1000);
    let tris = mesh.indices.len();
    let shapes = vec![GeoShape {
        surface: Surface::Mesh(mesh),
        flip_normals: false,
    }];
    let mut g = c.benchmark_group(format!("bvh_build/sphere_{tris}_tris"));
    g.sample_size(10);
    g.bench_function("build", |b| {
        b.iter(|| black_box(Geometry::build(shapes.clone())))
    });
    g.finish();
    let geometry = Geometry::build(shapes);
    let rays = random_rays(Vec3::splat(-0.7), Vec3::splat(0.7), 100_000);
    bench_rays(c, &format!("sphere_{tris}_tris"), &geometry, &rays);
}

criterion_group!(benches, cornell, million);
criterion_main!(benches);
