//! The simulator's worlds: ray casting against closed-form answers, the BVH against a
//! brute-force scan, determinism of the generators, and room for robots to drive.

use std::collections::VecDeque;
use std::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_2, FRAC_PI_4, PI};

use nalgebra::{Point3, Unit, Vector3};
use olmap::sim::{
    box_room, corridor, free_spot, lab, office, Material, Object, Shape, SimRng, World, WorldKind,
};

const TOL: f64 = 1e-12;

fn p(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x, y, z)
}

fn unit(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z).normalize()
}

fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} != {b} (tol {tol})");
}

fn assert_vec(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64, what: &str) {
    assert!((a - b).norm() <= tol, "{what}: {a:?} != {b:?}");
}

/// The hit of one shape, asserting the normal is a unit vector facing the ray.
fn hit(s: &Shape, o: Point3<f64>, d: Vector3<f64>, max: f64) -> Option<(f64, Vector3<f64>)> {
    let h = s.intersect(&o, &d, max);
    if let Some((t, n)) = h {
        assert_close(n.norm(), 1.0, 1e-12, "normal length");
        assert!(n.dot(&d) < 0.0, "normal {n:?} does not face the ray {d:?}");
        assert!(t > 0.0 && t < max);
    }
    h
}

#[test]
fn plane_oblique_ray_closed_form() {
    let n = Vector3::new(1.0, -2.0, 2.0) / 3.0;
    let plane = Shape::Plane {
        normal: Unit::new_normalize(n),
        offset: 1.7,
    };
    let o = p(0.3, 0.4, -2.0);
    let d = unit(0.2, -0.5, 1.0);
    // n.(o + t d) = offset  =>  t = (offset - n.o) / n.d
    let n_o = (0.3 - 0.8 - 4.0) / 3.0;
    let n_d = (0.2 + 1.0 + 2.0) / 3.0 / (0.2f64 * 0.2 + 0.25 + 1.0).sqrt();
    let expect = (1.7 - n_o) / n_d;
    let (t, normal) = hit(&plane, o, d, 100.0).unwrap();
    assert_close(t, expect, TOL, "plane range");
    assert_vec(&normal, &(-n), TOL, "plane normal faces the origin side");
    let q = o + t * d;
    assert_close(n.dot(&q.coords), 1.7, 1e-12, "hit point on plane");
    // From the other side the normal flips.
    let o2 = o + 2.0 * t * d;
    let (t2, normal2) = hit(&plane, o2, -d, 100.0).unwrap();
    assert_close(t2, t, 1e-12, "range from the far side");
    assert_vec(&normal2, &n, TOL, "flipped normal");
    // Away from the plane, parallel to it, beyond max.
    assert!(plane.intersect(&o, &-d, 100.0).is_none());
    let along = unit(2.0, 1.0, 0.0); // n.along = 0
    assert!(plane.intersect(&o, &along, 100.0).is_none());
    assert!(plane.intersect(&o, &d, expect - 1e-6).is_none());
    assert!(plane.intersect(&o, &d, expect + 1e-6).is_some());

    let floor = Shape::horizontal_plane(0.5);
    let (t, normal) = hit(&floor, p(1.0, 2.0, 3.0), unit(1.0, 1.0, -1.0), 10.0).unwrap();
    assert_close(t, 2.5 * 3f64.sqrt(), TOL, "horizontal plane");
    assert_vec(&normal, &Vector3::z(), TOL, "floor normal up");
}

#[test]
fn cylinder_side_at_offset_from_axis() {
    let (r, big_d, b) = (0.5, 5.0, 0.3);
    let cyl = Shape::Cylinder {
        base: p(2.0, 3.0, 0.0),
        radius: r,
        height: 2.0,
    };
    // Horizontal ray passing the axis at distance b: t = D - sqrt(r^2 - b^2).
    let chord = (r * r - b * b).sqrt();
    let (t, n) = hit(&cyl, p(2.0 - big_d, 3.0 + b, 1.0), Vector3::x(), 20.0).unwrap();
    assert_close(t, big_d - chord, TOL, "side range");
    assert_vec(
        &n,
        &Vector3::new(-chord / r, b / r, 0.0),
        TOL,
        "side normal",
    );
    // The same ray rising at 20 degrees: the horizontal distance is the same.
    let e = 20f64.to_radians();
    let d = Vector3::new(e.cos(), 0.0, e.sin());
    let (t, n) = hit(&cyl, p(2.0 - big_d, 3.0 + b, 0.1), d, 20.0).unwrap();
    assert_close(t, (big_d - chord) / e.cos(), TOL, "oblique side range");
    assert_close(n.z, 0.0, TOL, "side normal horizontal");
    // In a general horizontal direction, the offset from the axis is |(c - o) x d|.
    let o = p(-1.0, 1.0, 1.5);
    let d = unit(3.0, 2.2, 0.0);
    let to_c = Vector3::new(3.0, 2.0, 0.0);
    let off = to_c.cross(&d).norm();
    let along = to_c.dot(&d);
    let (t, _) = hit(&cyl, o, d, 20.0).unwrap();
    assert_close(
        t,
        along - (r * r - off * off).sqrt(),
        1e-12,
        "general side range",
    );
    // Just outside the radius misses; so does a ray over the top.
    assert!(cyl
        .intersect(&p(2.0 - big_d, 3.0 + 0.5001, 1.0), &Vector3::x(), 20.0)
        .is_none());
    assert!(cyl
        .intersect(&p(2.0 - big_d, 3.0, 2.01), &Vector3::x(), 20.0)
        .is_none());
    // From inside: the far wall, normal facing back in.
    let (t, n) = hit(&cyl, p(2.0 - 0.1, 3.0 + b, 1.0), Vector3::x(), 20.0).unwrap();
    assert_close(t, 0.1 + chord, TOL, "exit range");
    assert_vec(
        &n,
        &Vector3::new(-chord / r, -b / r, 0.0),
        TOL,
        "exit normal",
    );
    // max is respected.
    assert!(cyl
        .intersect(
            &p(2.0 - big_d, 3.0 + b, 1.0),
            &Vector3::x(),
            big_d - chord - 1e-9
        )
        .is_none());
}

#[test]
fn cylinder_caps() {
    let cyl = Shape::Cylinder {
        base: p(2.0, 3.0, 0.5),
        radius: 0.5,
        height: 2.0,
    };
    // Straight down onto the top cap.
    let (t, n) = hit(&cyl, p(2.2, 2.9, 5.0), -Vector3::z(), 20.0).unwrap();
    assert_close(t, 2.5, TOL, "top cap");
    assert_vec(&n, &Vector3::z(), TOL, "top normal");
    // Obliquely onto the top cap: from (1, 3, 4.5) along (1, 0, -2)/sqrt5 meets z = 2.5 at
    // t = sqrt5, x = 2 (the centre).
    let (t, n) = hit(&cyl, p(1.0, 3.0, 4.5), unit(1.0, 0.0, -2.0), 20.0).unwrap();
    assert_close(t, 5f64.sqrt(), TOL, "oblique top cap");
    assert_vec(&n, &Vector3::z(), TOL, "oblique top normal");
    // Up onto the bottom cap.
    let (t, n) = hit(&cyl, p(1.8, 3.1, -1.0), Vector3::z(), 20.0).unwrap();
    assert_close(t, 1.5, TOL, "bottom cap");
    assert_vec(&n, &-Vector3::z(), TOL, "bottom normal");
    // A steep ray that would meet the infinite cylinder above the top misses the cap
    // when it lands outside the disc.
    assert!(cyl
        .intersect(&p(2.6, 3.0, 5.0), &-Vector3::z(), 20.0)
        .is_none());
}

/// The unit cube [0, 1]^3 as a box.
fn cube() -> Shape {
    Shape::aabb_box(p(0.0, 0.0, 0.0), p(1.0, 1.0, 1.0))
}

#[test]
fn box_faces_near_a_corner() {
    let c = cube();
    // Straight at each of the two faces meeting at the vertical edge x = y = 0.
    let (t, n) = hit(&c, p(-2.0, 0.02, 0.5), Vector3::x(), 10.0).unwrap();
    assert_close(t, 2.0, TOL, "x face");
    assert_vec(&n, &-Vector3::x(), TOL, "x face normal");
    let (t, n) = hit(&c, p(0.02, -3.0, 0.5), Vector3::y(), 10.0).unwrap();
    assert_close(t, 3.0, TOL, "y face");
    assert_vec(&n, &-Vector3::y(), TOL, "y face normal");
    // Diagonal rays just either side of the edge.
    let d = unit(1.0, 1.0, 0.0);
    let (t, n) = hit(&c, p(-1.0, -0.9, 0.5), d, 10.0).unwrap();
    assert_close(t, 2f64.sqrt(), TOL, "diagonal onto x face");
    assert_vec(&n, &-Vector3::x(), TOL, "diagonal x normal");
    let (t, n) = hit(&c, p(-0.9, -1.0, 0.5), d, 10.0).unwrap();
    assert_close(t, 2f64.sqrt(), TOL, "diagonal onto y face");
    assert_vec(&n, &-Vector3::y(), TOL, "diagonal y normal");
    // Exactly through the edge: the range is exact, the normal one of the two faces'.
    let (t, n) = hit(&c, p(-1.0, -1.0, 0.5), d, 10.0).unwrap();
    assert_close(t, 2f64.sqrt(), TOL, "through the edge");
    assert!(
        (n + Vector3::x()).norm() < TOL || (n + Vector3::y()).norm() < TOL,
        "edge normal {n:?}"
    );
    // Through the corner vertex itself.
    let (t, _) = hit(&c, p(-1.0, -1.0, -1.0), unit(1.0, 1.0, 1.0), 10.0).unwrap();
    assert_close(t, 3f64.sqrt(), TOL, "through the vertex");
    // Across the edge (perpendicular to the diagonal): a hair outside misses, a hair
    // inside clips the corner.
    let across = unit(1.0, -1.0, 0.0);
    assert!(c
        .intersect(&p(-1.0, 1.0 - 1e-6, 0.5), &across, 10.0)
        .is_none());
    let (t, _) = hit(&c, p(-1.0, 1.0 + 1e-6, 0.5), across, 10.0).unwrap();
    assert_close(t, 2f64.sqrt(), 1e-5, "clipping the edge");
    // From inside: the exit face, normal facing back in.
    let (t, n) = hit(&c, p(0.25, 0.5, 0.5), Vector3::x(), 10.0).unwrap();
    assert_close(t, 0.75, TOL, "exit face");
    assert_vec(&n, &-Vector3::x(), TOL, "exit normal");
    let (t, n) = hit(&c, p(0.5, 0.5, 0.5), unit(0.0, 1.0, 1.0), 10.0).unwrap();
    assert_close(t, 0.5 * 2f64.sqrt(), TOL, "exit through an edge");
    assert!(n.dot(&Vector3::new(0.0, 1.0, 1.0)) < 0.0);
    // Misses, pointing away, and max.
    assert!(c
        .intersect(&p(-2.0, 1.5, 0.5), &Vector3::x(), 10.0)
        .is_none());
    assert!(c
        .intersect(&p(-2.0, 0.5, 0.5), &-Vector3::x(), 10.0)
        .is_none());
    assert!(c
        .intersect(&p(-2.0, 0.5, 0.5), &Vector3::x(), 1.999)
        .is_none());
    assert!(c
        .intersect(&p(-2.0, 0.5, 0.5), &Vector3::x(), 2.001)
        .is_some());
}

#[test]
fn yawed_boxes() {
    // Half-extents (1, 0.5, 1) turned 45 degrees: along its centre line y = 0 the ray
    // enters where the local |y| = r / sqrt2 reaches 0.5, i.e. r = sqrt2 / 2 before the
    // centre, through the local +y face whose world normal is (-1, 1, 0) / sqrt2.
    let b = Shape::Box {
        center: p(5.0, 0.0, 1.0),
        half: Vector3::new(1.0, 0.5, 1.0),
        yaw: FRAC_PI_4,
    };
    let (t, n) = hit(&b, p(0.0, 0.0, 1.0), Vector3::x(), 20.0).unwrap();
    assert_close(t, 5.0 - FRAC_1_SQRT_2, TOL, "45 degree box range");
    assert_vec(
        &n,
        &Vector3::new(-FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0),
        TOL,
        "45 degree normal",
    );
    // Along the box's own long axis: hits the end face at the half-length.
    let along = Vector3::new(FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0);
    let (t, n) = hit(&b, p(5.0, 0.0, 1.0) - 4.0 * along, along, 20.0).unwrap();
    assert_close(t, 3.0, TOL, "along the long axis");
    assert_vec(&n, &-along, TOL, "end face normal");
    // A quarter turn swaps the extents.
    let q = Shape::Box {
        center: p(0.0, 5.0, 1.0),
        half: Vector3::new(2.0, 0.5, 1.0),
        yaw: FRAC_PI_2,
    };
    let (t, n) = hit(&q, p(0.0, 0.0, 1.0), Vector3::y(), 20.0).unwrap();
    assert_close(t, 3.0, TOL, "quarter turn, long side");
    assert_vec(&n, &-Vector3::y(), TOL, "quarter turn normal");
    let (t, _) = hit(&q, p(-5.0, 5.0, 1.0), Vector3::x(), 20.0).unwrap();
    assert_close(t, 4.5, TOL, "quarter turn, short side");
    // Bounds of a turned box hold every corner.
    let bb = b.bounds().unwrap();
    assert_close(bb.max.x - 5.0, 1.5 * FRAC_1_SQRT_2, 1e-12, "yawed bounds");
    // A ray down through a corner of the unturned box clears the turned one.
    let down = -Vector3::z();
    assert!(b.intersect(&p(5.95, -0.45, 5.0), &down, 20.0).is_none());
    let unturned = Shape::Box {
        center: p(5.0, 0.0, 1.0),
        half: Vector3::new(1.0, 0.5, 1.0),
        yaw: 0.0,
    };
    let (t, _) = hit(&unturned, p(5.95, -0.45, 5.0), down, 20.0).unwrap();
    assert_close(t, 3.0, TOL, "unturned top");
    // Yaw by a full turn is the same box.
    let full = Shape::Box {
        center: p(5.0, 0.0, 1.0),
        half: Vector3::new(1.0, 0.5, 1.0),
        yaw: FRAC_PI_4 + 2.0 * PI,
    };
    let (t2, _) = full
        .intersect(&p(0.0, 0.0, 1.0), &Vector3::x(), 20.0)
        .unwrap();
    assert_close(t2, 5.0 - FRAC_1_SQRT_2, 1e-9, "yaw + 2 pi");
}

#[test]
fn box_room_planes() {
    let room = box_room(Vector3::new(8.0, 6.0, 3.0));
    let o = p(2.0, 3.0, 1.0);
    for (d, expect, normal) in [
        (Vector3::x(), 6.0, -Vector3::x()),
        (-Vector3::x(), 2.0, Vector3::x()),
        (Vector3::y(), 3.0, -Vector3::y()),
        (-Vector3::y(), 3.0, Vector3::y()),
        (Vector3::z(), 2.0, -Vector3::z()),
        (-Vector3::z(), 1.0, Vector3::z()),
    ] {
        let h = room.cast(&o, &d, 50.0).unwrap();
        assert_close(h.distance, expect, TOL, "box room wall");
        assert_vec(&h.normal, &normal, TOL, "box room normal");
        assert_eq!(h.id, 0);
        assert_eq!(h.material, Material::WALL);
        assert!(room.cast(&o, &d, expect - 1e-9).is_none(), "max respected");
    }
    // Oblique into the far corner region: the wall x = 8 at t = 6 / cos.
    let d = unit(6.0, 1.0, 0.5);
    let h = room.cast(&o, &d, 50.0).unwrap();
    assert_close(h.distance, 6.0 / d.x, TOL, "oblique to the wall");
    // The room's inside is clear for a robot away from the walls.
    for i in 0..=14 {
        for j in 0..=10 {
            let (x, y) = (0.3 + i as f64 * 0.5, 0.3 + j as f64 * 0.5);
            assert!(room.is_clear(x, y, 0.25, 0.05, 1.0), "({x}, {y})");
        }
    }
    assert!(!room.is_clear(0.2, 3.0, 0.25, 0.05, 1.0));
    let b = room.bounds().unwrap();
    assert_vec(
        &b.min.coords,
        &Vector3::new(-0.1, -0.1, -0.1),
        TOL,
        "bounds",
    );
    assert_vec(&b.max.coords, &Vector3::new(8.1, 6.1, 3.1), TOL, "bounds");
}

/// Brute force: the nearest hit over every object, and every object index at that range.
fn brute(
    objects: &[Object],
    o: &Point3<f64>,
    d: &Vector3<f64>,
    max: f64,
) -> Option<(f64, Vec<u32>)> {
    let hits: Vec<(f64, u32)> = objects
        .iter()
        .filter_map(|ob| ob.shape.intersect(o, d, max).map(|(t, _)| (t, ob.id)))
        .collect();
    let best = hits.iter().map(|h| h.0).min_by(f64::total_cmp)?;
    let ids = hits.iter().filter(|h| h.0 == best).map(|h| h.1).collect();
    Some((best, ids))
}

/// The world with each object's id set to its index, so hits name their object.
fn indexed(w: &World) -> World {
    let objects = w
        .objects()
        .iter()
        .enumerate()
        .map(|(i, o)| Object {
            id: i as u32,
            ..o.clone()
        })
        .collect();
    World::new(w.name(), objects)
}

fn bvh_matches_brute_force(world: &World, seed: u64) {
    let w = indexed(world);
    let b = w.bounds().unwrap();
    let mut rng = SimRng::new(seed);
    let axes = [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
    ];
    let mut hits = 0;
    for k in 0..20_000 {
        let mut o = p(
            rng.range(b.min.x, b.max.x),
            rng.range(b.min.y, b.max.y),
            rng.range(b.min.z, b.max.z),
        );
        // Some rays along the axes, some starting on round coordinates (on faces).
        let d = if rng.chance(0.1) {
            axes[rng.index(6)]
        } else {
            Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize()
        };
        if rng.chance(0.05) {
            o = p(o.x.round(), o.y.round(), o.z.round());
        }
        let max = if rng.chance(0.5) {
            100.0
        } else {
            rng.range(0.1, 20.0)
        };
        let got = w.cast(&o, &d, max);
        let want = brute(w.objects(), &o, &d, max);
        match (got, want) {
            (None, None) => {}
            (Some(h), Some((t, ids))) => {
                hits += 1;
                assert!(
                    (h.distance - t).abs() <= 1e-12,
                    "ray {k}: bvh {} vs brute {t}",
                    h.distance
                );
                assert!(ids.contains(&h.id), "ray {k}: id {} not in {ids:?}", h.id);
            }
            (g, w) => panic!("ray {k} from {o:?} along {d:?}: bvh {g:?} vs brute {w:?}"),
        }
    }
    assert!(hits > 10_000, "{hits} hits only");
}

#[test]
fn bvh_equals_brute_force_lab() {
    bvh_matches_brute_force(&lab(1), 11);
}

#[test]
fn bvh_equals_brute_force_office() {
    bvh_matches_brute_force(&office(2), 12);
}

#[test]
fn cast_many_equals_cast() {
    let w = office(3);
    let mut rng = SimRng::new(5);
    let (x, y) = free_spot(&w, &mut rng, 0.3).unwrap();
    let o = p(x, y, 0.8);
    let rays: Vec<_> = (0..3000)
        .map(|_| {
            let d = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            (o, d)
        })
        .collect();
    let many = w.cast_many(&[], &rays, 30.0);
    for ((o, d), h) in rays.iter().zip(&many) {
        assert_eq!(*h, w.cast(o, d, 30.0));
    }
    assert!(
        many.iter().all(Option::is_some),
        "closed world: every ray hits"
    );
}

#[test]
fn generators_are_deterministic() {
    for kind in WorldKind::ALL {
        assert_eq!(kind.build(4).objects(), kind.build(4).objects(), "{kind}");
    }
    assert_eq!(lab(7).objects(), lab(7).objects());
    assert_ne!(lab(7).objects(), lab(8).objects());
    assert_eq!(office(7).objects(), office(7).objects());
    assert_ne!(office(7).objects(), office(8).objects());
    // A seed changes the layout, not a few decimals: the object counts or positions differ
    // well beyond rounding.
    let (a, b) = (lab(1), lab(2));
    let moved = a
        .objects()
        .iter()
        .zip(b.objects())
        .filter(|(x, y)| x.shape != y.shape)
        .count();
    assert!(moved > 10 || a.objects().len() != b.objects().len());
}

#[test]
fn world_kind_names() {
    for kind in WorldKind::ALL {
        assert_eq!(kind.name().parse::<WorldKind>(), Ok(kind));
        assert_eq!(kind.build(1).name(), kind.name());
    }
    assert_eq!("office".parse(), Ok(WorldKind::Office));
    assert_eq!("box-room".parse(), Ok(WorldKind::BoxRoom));
    let err = "Lab".parse::<WorldKind>().unwrap_err();
    assert!(err.contains("Lab") && err.contains("box-room"), "{err}");
    assert!("".parse::<WorldKind>().is_err());
}

#[test]
fn world_contents() {
    for seed in 0..5 {
        for w in [lab(seed), office(seed), corridor(seed)] {
            assert!(w.objects().iter().all(|o| o.id == 0));
            assert!(w
                .objects()
                .iter()
                .all(|o| o.material == Material::WALL || o.material == Material::FURNITURE));
        }
        let l = lab(seed);
        let b = l.bounds().unwrap();
        assert_vec(
            &b.min.coords,
            &Vector3::new(-0.2, -0.2, -0.2),
            TOL,
            "lab min",
        );
        assert_vec(
            &b.max.coords,
            &Vector3::new(20.2, 20.2, 3.2),
            TOL,
            "lab max",
        );
        let pillars = l
            .objects()
            .iter()
            .filter(|o| matches!(o.shape, Shape::Cylinder { height, .. } if height >= 3.0))
            .count();
        assert_eq!(pillars, 3);
        let bins = l
            .objects()
            .iter()
            .filter(|o| matches!(o.shape, Shape::Cylinder { height, .. } if height < 1.0))
            .count();
        let yawed = l
            .objects()
            .iter()
            .filter(|o| matches!(o.shape, Shape::Box { yaw, .. } if (0.01..FRAC_PI_2 - 0.01).contains(&yaw.rem_euclid(FRAC_PI_2))))
            .count();
        assert!(
            l.objects().len() > 40,
            "lab {seed}: {} objects",
            l.objects().len()
        );
        assert!(yawed > 0, "lab {seed} has no yawed furniture");
        let _ = bins;

        // Office: the stairwell rises above the 3 m ceiling and is open at the top.
        let o = office(seed);
        let b = o.bounds().unwrap();
        assert_close(b.max.z, 6.0, TOL, "stairwell height");
        assert!(b.max.x - b.min.x > 30.0 && b.max.x - b.min.x < 41.0);
        assert!(b.max.y - b.min.y > 14.0 && b.max.y - b.min.y < 16.0);
        let shaft_wall = o
            .objects()
            .iter()
            .filter_map(|ob| ob.shape.bounds())
            .find(|bb| bb.max.z > 5.9 && bb.max.y - bb.min.y < 0.3 && bb.max.x - bb.min.x > 1.0)
            .expect("the shaft's wall to the corridor");
        let mid_x = 0.5 * (shaft_wall.min.x + shaft_wall.max.x);
        // Inside the shaft, 4 m up, nothing above; under the ceiling, the ceiling.
        let inside = p(mid_x, 12.0, 4.0);
        assert!(
            o.cast(&inside, &Vector3::z(), 100.0).is_none(),
            "shaft is open"
        );
        let h = o.cast(&p(mid_x, 7.5, 1.0), &Vector3::z(), 100.0).unwrap();
        assert_close(h.distance, 2.0, TOL, "corridor ceiling");
        // The corridor is 2 m wide.
        let y0 = o.cast(&p(mid_x, 7.5, 2.5), &-Vector3::y(), 100.0).unwrap();
        let y1 = o.cast(&p(mid_x, 7.5, 2.5), &Vector3::y(), 100.0).unwrap();
        assert_close(y0.distance + y1.distance, 2.0, TOL, "corridor width");

        let c = corridor(seed);
        let b = c.bounds().unwrap();
        assert_close(b.max.x - b.min.x, 40.4, TOL, "corridor length");
        assert_eq!(c.objects().len(), 6);
    }
}

/// Free cells of a 10 cm grid (robot radius `r`) and the share of them in the largest
/// 4-connected component.
fn connectivity(w: &World, r: f64) -> (usize, f64) {
    let b = w.bounds().unwrap();
    let step = 0.1;
    let nx = ((b.max.x - b.min.x) / step) as usize;
    let ny = ((b.max.y - b.min.y) / step) as usize;
    let free: Vec<bool> = (0..nx * ny)
        .map(|k| {
            let (i, j) = (k % nx, k / nx);
            let x = b.min.x + (i as f64 + 0.5) * step;
            let y = b.min.y + (j as f64 + 0.5) * step;
            w.is_clear(x, y, r, 0.05, 1.0)
        })
        .collect();
    let total = free.iter().filter(|f| **f).count();
    let mut seen = vec![false; free.len()];
    let mut largest = 0;
    for start in 0..free.len() {
        if !free[start] || seen[start] {
            continue;
        }
        let mut size = 0;
        let mut queue = VecDeque::from([start]);
        seen[start] = true;
        while let Some(k) = queue.pop_front() {
            size += 1;
            let (i, j) = (k % nx, k / nx);
            let mut visit = |n: usize| {
                if free[n] && !seen[n] {
                    seen[n] = true;
                    queue.push_back(n);
                }
            };
            if i > 0 {
                visit(k - 1);
            }
            if i + 1 < nx {
                visit(k + 1);
            }
            if j > 0 {
                visit(k - nx);
            }
            if j + 1 < ny {
                visit(k + nx);
            }
        }
        largest = largest.max(size);
    }
    (total, largest as f64 / total as f64)
}

#[test]
fn robots_can_drive_around() {
    for seed in 1..4 {
        let (free, share) = connectivity(&lab(seed), 0.3);
        // 400 m^2 room: the margin and aisles alone are about 200 m^2.
        assert!(free > 20_000, "lab {seed}: {free} free cells");
        assert!(share > 0.95, "lab {seed}: largest component {share}");
        let (free, share) = connectivity(&office(seed), 0.3);
        assert!(free > 25_000, "office {seed}: {free} free cells");
        assert!(share > 0.95, "office {seed}: largest component {share}");
    }
}

#[test]
fn free_spots_are_free_and_inside() {
    for (w, n) in [
        (lab(1), 50),
        (office(1), 50),
        (corridor(1), 50),
        (box_room(Vector3::new(8.0, 6.0, 3.0)), 20),
    ] {
        let b = w.bounds().unwrap();
        let mut rng = SimRng::new(3);
        for _ in 0..n {
            let (x, y) = free_spot(&w, &mut rng, 0.35).unwrap_or_else(|| panic!("{}", w.name()));
            assert!(w.is_clear(x, y, 0.35, 0.05, 1.0));
            // Inside the walls, not in them: strictly within the inner floor.
            assert!(
                x > b.min.x + 0.2 && x < b.max.x - 0.2 && y > b.min.y + 0.2 && y < b.max.y - 0.2
            );
            let down = w.cast(&p(x, y, 0.5), &-Vector3::z(), 10.0).unwrap();
            assert_close(down.distance, 0.5, 1e-9, "floor under a free spot");
        }
    }
    // A robot wider than the corridor fits nowhere.
    assert_eq!(free_spot(&corridor(1), &mut SimRng::new(1), 1.1), None);
    // Outside every wall: a world of one free-standing wall has no enclosed spot.
    let wall = World::new(
        "wall",
        vec![Object {
            shape: Shape::aabb_box(p(0.0, 0.0, 0.0), p(10.0, 0.2, 3.0)),
            material: Material::WALL,
            id: 0,
        }],
    );
    assert_eq!(free_spot(&wall, &mut SimRng::new(1), 0.05), None);
}
