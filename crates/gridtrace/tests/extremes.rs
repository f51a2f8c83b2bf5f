//! Geometry extremes: a single triangle, a planar scene, long slivers, coordinates offset by
//! 1e6, a scene 1e-6 across, a camera inside a closed mesh; and shadow acne at grazing light.
//! Traversal must equal brute force on each (adversarial rays from `testing::ray_set`).

use glam::{Mat4, Vec3};
use gridtrace::AccelParams;
use gridtrace::accel::{
    Accel, AccelKind, Hit, NoCounters, Ray, Resolution, TriAccel, brute_force_intersect, brute_force_occluded,
};
use gridtrace::scene::{Camera, Material, PointLight, Scene, procedural};
use gridtrace::testing::{AllAccels, ray_set};
use gridtrace::{Mode, RenderOptions};
use rayon::prelude::*;

fn tris_of(m: &gridtrace::Mesh) -> Vec<TriAccel> {
    TriAccel::from_mesh(m)
}

/// Grid and pc closest hits equal brute force (hit/miss, relative t) for 20,000 rays.
fn check(name: &str, tris: Vec<TriAccel>, res: Resolution) {
    let all = AllAccels::build(tris, res).unwrap();
    let rays = ray_set(&all.grid, 20_000, 0x5EED ^ name.len() as u64);
    for kind in AccelKind::ALL {
        let bad: Vec<(Ray, Hit, Hit)> = rays
            .par_iter()
            .filter_map(|r| {
                let want = brute_force_intersect(&all.grid.tris, r);
                let got = all.get(kind).intersect(r, &mut NoCounters);
                let ok = got.is_hit() == want.is_hit()
                    && (!want.is_hit() || (got.t - want.t).abs() <= 1e-6 * want.t.abs())
                    && all.get(kind).occluded(r, &mut NoCounters) == want.is_hit();
                (!ok).then_some((*r, got, want))
            })
            .collect();
        assert!(
            bad.is_empty(),
            "{name} {}: {} rays disagree: {:?}",
            kind.name(),
            bad.len(),
            &bad[..bad.len().min(3)]
        );
    }
}

#[test]
fn single_triangle() {
    let t = TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y);
    check("single", vec![t], Resolution::default());
    check("single-fine", vec![t], Resolution::Fixed([9, 9, 1]));
    let accel = Accel::build(vec![t], AccelKind::ProximityCloud, &AccelParams::NONE).unwrap();
    let h = accel.intersect(&Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z), &mut NoCounters);
    assert_eq!((h.tri, h.t), (0, 1.0));
}

#[test]
fn all_triangles_in_one_plane() {
    // An axis-aligned plane (the grid is one cell thick) and a tilted one.
    let m = procedural::plane(2.0, 40);
    check("plane-y", tris_of(&m), Resolution::default());
    let mut tilted = m.clone();
    procedural::transform(&mut tilted, Mat4::from_rotation_x(0.3) * Mat4::from_rotation_z(0.2));
    check("plane-tilted", tris_of(&tilted), Resolution::default());
}

#[test]
fn long_thin_slivers() {
    let mut tris = Vec::new();
    for i in 0..200 {
        let y = i as f32 * 0.01;
        let z = (i % 7) as f32 * 0.013;
        tris.push(TriAccel::new(
            Vec3::new(-10.0, y, z),
            Vec3::new(10.0, y + 1e-4, z),
            Vec3::new(10.0, y, z + 2e-4),
        ));
        // Diagonal slivers across the whole box.
        tris.push(TriAccel::new(
            Vec3::new(-10.0, -1.0, -1.0 + y),
            Vec3::new(10.0, 3.0, 1.0 + y),
            Vec3::new(10.0, 3.0 + 1e-3, 1.0 + y),
        ));
    }
    check("slivers", tris.clone(), Resolution::default());
    check("slivers-fine", tris, Resolution::Fixed([64, 16, 16]));
}

#[test]
fn huge_coordinate_offset() {
    let m = procedural::icosphere(Vec3::splat(1e6), 1.0, 3);
    check("offset-1e6", tris_of(&m), Resolution::default());
    let m = procedural::torus_knot(2, 3, 0.16, 48, 6);
    let mut far = m.clone();
    procedural::transform(&mut far, Mat4::from_translation(Vec3::new(-1e6, 3e5, 1e6)));
    check("knot-offset-1e6", tris_of(&far), Resolution::default());
}

#[test]
fn tiny_scene() {
    let mut m = procedural::torus_knot(2, 3, 0.16, 48, 6);
    procedural::transform(&mut m, Mat4::from_scale(Vec3::splat(1e-6)));
    check("tiny-1e-6", tris_of(&m), Resolution::default());
    let m = procedural::icosphere(Vec3::new(1e-6, 0.0, 0.0), 1e-6, 2);
    check("tiny-sphere", tris_of(&m), Resolution::default());
}

/// A camera inside a closed mesh sees the mesh in every pixel (CPU render in cast mode), and
/// rays from inside in every direction hit it.
#[test]
fn camera_inside_a_mesh() {
    let mut s = Scene::default();
    s.add_mesh(procedural::icosphere(Vec3::ZERO, 1.0, 3), Mat4::IDENTITY, None);
    s.camera = Camera {
        eye: Vec3::new(0.1, 0.2, 0.05),
        target: Vec3::new(1.0, 0.3, 0.0),
        up: Vec3::Y,
        vfov_deg: 100.0,
    };
    s.background = Vec3::new(1.0, 0.0, 1.0);
    s.lights.push(PointLight::new(Vec3::new(0.0, 0.5, 0.0), Vec3::ONE));
    for kind in AccelKind::ALL {
        let p = s.prepare_for(kind, &AccelParams::NONE).unwrap();
        let (img, _) = gridtrace::cpu::render(&p, &RenderOptions::new(96, 64, Mode::Shadow), None).unwrap();
        let bg = img.pixels().iter().filter(|c| **c == s.background).count();
        assert_eq!(bg, 0, "{} background pixels seen from inside", bg);
        assert!(img.pixels().iter().all(|c| c.is_finite()));
    }
}

/// Shadow acne: a plane and a sphere lit at grazing angles (the light 3 and 8 degrees above
/// the plane). Every pixel of the lit side that the light clearly sees (geometric and shading
/// N.L > 0.03, and no *other* object within a small cone towards the light) must be unshadowed:
/// its colour is more than the ambient term. Checked on the CPU and, unless skipped, the GPU.
#[test]
fn no_shadow_acne_at_grazing_light() {
    for elevation_deg in [3.0f32, 8.0] {
        let mut s = Scene::default();
        let plane = procedural::plane(8.0, 16);
        let sphere = procedural::icosphere(Vec3::new(0.0, 0.8, 0.0), 0.8, 4);
        let grey = Material {
            diffuse: Vec3::splat(0.8),
            ..Material::default()
        };
        s.add_mesh(plane.clone(), Mat4::IDENTITY, Some(grey.clone()));
        s.add_mesh(sphere.clone(), Mat4::IDENTITY, Some(grey));
        let n_plane = plane.triangles.len();
        let e = elevation_deg.to_radians();
        let light = Vec3::new(-e.cos(), e.sin(), 0.3).normalize() * 30.0;
        s.lights.push(PointLight::new(light, Vec3::splat(900.0 * 4.0)));
        s.ambient = Vec3::splat(0.05);
        s.camera = Camera {
            eye: Vec3::new(2.0, 3.0, 5.0),
            target: Vec3::new(0.0, 0.3, 0.0),
            up: Vec3::Y,
            vfov_deg: 60.0,
        };
        let p = s.prepare(Resolution::default()).unwrap();
        let (w, h) = (160, 120);
        let frame = p.camera.frame(w, h);
        // Other-object triangles, for the reference visibility.
        let plane_tris = &p.accel.tris[..n_plane];
        let sphere_tris = &p.accel.tris[n_plane..];
        assert_eq!(p.degenerate_dropped, 0);
        let mut images = vec![(
            "cpu",
            gridtrace::cpu::render(&p, &RenderOptions::new(w, h, Mode::Shadow), None)
                .unwrap()
                .0,
        )];
        if std::env::var_os("GRIDTRACE_SKIP_GPU").is_none() {
            let ctx = gridtrace::gpu::GpuContext::new().expect("GPU adapter");
            let mut gpu =
                gridtrace::gpu::GpuRenderer::new(std::sync::Arc::new(ctx), &p, &gridtrace::gpu::GpuVariants::default())
                    .unwrap();
            let opts = RenderOptions::new(w, h, Mode::Shadow);
            images.push(("gpu", gpu.render(&p.camera, &p.lights, &opts).unwrap().0));
        }
        let mut checked = 0;
        for (backend, img) in &images {
            let mut acne = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    let r = frame.ray(x, y);
                    let hit = p.accel.intersect(&r, &mut NoCounters);
                    if !hit.is_hit() {
                        continue;
                    }
                    let surf = gridtrace::cpu::surface_at(&p, &r, &hit);
                    let to_light = light - surf.position;
                    let l = to_light.normalize();
                    if surf.ng.dot(l) < 0.03 || surf.ns.dot(l) < 0.03 {
                        continue;
                    }
                    let others = if (hit.tri as usize) < n_plane {
                        sphere_tris
                    } else {
                        plane_tris
                    };
                    // Clearly visible: the light and four points around it are unoccluded.
                    let side = l.any_orthonormal_vector() * 0.6;
                    let up = l.cross(side);
                    let clear = [Vec3::ZERO, side, -side, up, -up].iter().all(|&d| {
                        let ray = Ray::new(surf.position, light + d - surf.position);
                        !brute_force_occluded(others, &gridtrace::testing::within(&ray, 1e-4, 1.0))
                    });
                    if !clear {
                        continue;
                    }
                    if *backend == "cpu" {
                        checked += 1;
                    }
                    let c = img.pixels()[(y * w + x) as usize];
                    let ambient = 0.05 * 0.8;
                    if c.x <= ambient * 1.2 {
                        acne.push((x, y, c));
                    }
                }
            }
            assert!(
                acne.is_empty(),
                "{backend}, light {elevation_deg} degrees: {} self-shadowed pixels, first {:?}",
                acne.len(),
                &acne[..acne.len().min(5)]
            );
        }
        assert!(checked > 3000, "only {checked} pixels checked");
    }
}

/// Found by the traverse fuzz target: a 10,000-long, 0.06-wide sliver and a ray from 10,000
/// units away. Möller-Trumbore's u cancelled catastrophically (terms of 3e8 for a result of a
/// few units) and reported a hit 3 units beyond the sliver's end, where the grid rightly never
/// looks. The watertight test decides inside/outside from the sheared vertices, so a hit it
/// reports lies on the sliver up to the rounding of coordinates of 1e4 (about 1e-3).
#[test]
fn sliver_with_far_origin_has_no_hit_beyond_its_end() {
    let t = TriAccel::new(
        Vec3::new(0.0, 6.6174445e-24, 10000.0),
        Vec3::new(4.1816e-41, 0.0, 0.0),
        Vec3::new(-4.120587e-24, 0.057855222, 0.0),
    );
    let far = Ray::new(
        Vec3::new(-10000.0, -10000.0, 3.003961),
        Vec3::new(3.0039215, 3.0039215, 3.0039215),
    );
    if let Some(h) = t.intersect(far.origin, far.dir, 0.0, f32::INFINITY) {
        let p = far.at(h.t);
        assert!(p.z <= 10_000.01 && p.z >= -0.01, "hit at {p}, off the sliver");
    }
    // A well-shaped triangle seen from 10 units is hit where the ray meets it.
    let good = TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y);
    let r = Ray::new(Vec3::new(0.3, 0.3, 10.0), Vec3::new(0.01, -0.02, -1.0));
    let h = good.intersect(r.origin, r.dir, 0.0, f32::INFINITY).expect("a hit");
    assert!(
        (h.t - 10.0).abs() < 1e-5 && (h.u - 0.4).abs() < 1e-6 && (h.v - 0.1).abs() < 1e-6,
        "{h:?}"
    );
}
