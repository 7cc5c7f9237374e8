//! Procedural CAD parts of the corpus, built in code for this project (our own geometry, under the
//! workspace's license): a probing fixture plate, a thin sheet-metal bracket, an open housing
//! cover that is not watertight, and a near-symmetric turned part. They carry what real CAD has
//! and the project's own test parts lack: fillets and round holes tessellated into thousands of
//! triangles, 2.5 mm walls, a chamfer, an inclined face, a small symmetry-breaking feature, and
//! an open surface. Units are metres; dimensions below are written in millimetres times [`MM`].

use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::CorpusError;
use super::build::{Builder, at_z, circle, rotate_2d, rounded_rect};
use crate::geometry::{Mesh, MeshError};

const MM: f64 = 1e-3;

/// Vertical walls between two loops, split into `rings` bands, facing along `hint`.
fn wall(
    b: &mut Builder,
    bottom: &[Point3<f64>],
    top: &[Point3<f64>],
    rings: usize,
    hint: impl Fn(&Point3<f64>) -> Vector3<f64> + Copy,
) {
    let ring = |t: f64| -> Vec<Point3<f64>> {
        bottom
            .iter()
            .zip(top)
            .map(|(p, q)| Point3::from(p.coords + t * (q.coords - p.coords)))
            .collect()
    };
    let mut lower = bottom.to_vec();
    for k in 1..=rings {
        let upper = if k == rings {
            top.to_vec()
        } else {
            ring(k as f64 / rings as f64)
        };
        b.strip(&lower, &upper, true, hint);
        lower = upper;
    }
}

fn away_from(centre: [f64; 2]) -> impl Fn(&Point3<f64>) -> Vector3<f64> + Copy {
    move |p| Vector3::new(p.x - centre[0], p.y - centre[1], 0.0)
}

fn towards(centre: [f64; 2]) -> impl Fn(&Point3<f64>) -> Vector3<f64> + Copy {
    move |p| Vector3::new(centre[0] - p.x, centre[1] - p.y, 0.0)
}

fn scaled(outline: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    outline.into_iter().map(|[x, y]| [x * MM, y * MM]).collect()
}

/// A probing fixture about 180 x 130 mm, like the 3D-printed ones people hand-guide a robot
/// over: a 12 mm base plate with rounded vertical corners (R12) and a 2 mm chamfer round its top
/// edge, four through-holes (8 mm), a rounded pocket 6 mm deep, a cylindrical boss with a blind
/// bore, a small pin, and a block turned 15 degrees about z whose top is inclined 20 degrees.
/// Closed and outward-oriented; about 5k triangles.
pub fn fixture_plate() -> Result<Mesh, MeshError> {
    let mut b = Builder::new();
    let (plate_z, chamfer_z) = (10.0 * MM, 12.0 * MM);
    let outline = scaled(rounded_rect([0.0, 0.0], [180.0, 130.0], 12.0, 16, 6.0));
    // The chamfer's top edge: 2 mm in, the straight sides keep their length and their vertices.
    let inset = scaled(rounded_rect([0.0, 0.0], [176.0, 126.0], 10.0, 16, 6.0));
    let hole_centres = [[72.0, 47.0], [-72.0, 47.0], [-72.0, -47.0], [72.0, -47.0]];
    let holes: Vec<Vec<[f64; 2]>> = hole_centres
        .iter()
        .map(|&c| scaled(circle(c, 4.0, 48, 0.0)))
        .collect();
    let centre = [0.0, 0.0];
    wall(
        &mut b,
        &at_z(&outline, 0.0),
        &at_z(&outline, plate_z),
        3,
        away_from(centre),
    );
    b.strip(
        &at_z(&outline, plate_z),
        &at_z(&inset, chamfer_z),
        true,
        |p| Vector3::new(p.x, p.y, p.x.hypot(p.y)),
    );
    let bottom_holes: Vec<Vec<Point3<f64>>> = holes.iter().map(|h| at_z(h, 0.0)).collect();
    b.face(&at_z(&outline, 0.0), &bottom_holes, &-Vector3::z())?;
    for (hole, c) in holes.iter().zip(hole_centres) {
        let c = [c[0] * MM, c[1] * MM];
        wall(
            &mut b,
            &at_z(hole, 0.0),
            &at_z(hole, chamfer_z),
            3,
            towards(c),
        );
    }

    let mut top_holes: Vec<Vec<Point3<f64>>> = holes.iter().map(|h| at_z(h, chamfer_z)).collect();

    // Rounded pocket, 6 mm deep.
    let pocket_centre = [40.0 * MM, -32.0 * MM];
    let pocket = scaled(rounded_rect([40.0, -32.0], [44.0, 26.0], 5.0, 10, 4.0));
    let pocket_floor_z = 6.0 * MM;
    wall(
        &mut b,
        &at_z(&pocket, pocket_floor_z),
        &at_z(&pocket, chamfer_z),
        3,
        towards(pocket_centre),
    );
    b.face(&at_z(&pocket, pocket_floor_z), &[], &Vector3::z())?;
    top_holes.push(at_z(&pocket, chamfer_z));

    // Cylindrical boss (R18, 20 mm high) with a blind bore (R8, 12 mm deep).
    let boss_centre = [40.0 * MM, 22.0 * MM];
    let boss = scaled(circle([40.0, 22.0], 18.0, 96, 0.0));
    let bore = scaled(circle([40.0, 22.0], 8.0, 64, 0.0));
    let (boss_top_z, bore_floor_z) = (32.0 * MM, 20.0 * MM);
    wall(
        &mut b,
        &at_z(&boss, chamfer_z),
        &at_z(&boss, boss_top_z),
        4,
        away_from(boss_centre),
    );
    b.face(
        &at_z(&boss, boss_top_z),
        &[at_z(&bore, boss_top_z)],
        &Vector3::z(),
    )?;
    wall(
        &mut b,
        &at_z(&bore, bore_floor_z),
        &at_z(&bore, boss_top_z),
        4,
        towards(boss_centre),
    );
    b.face(&at_z(&bore, bore_floor_z), &[], &Vector3::z())?;
    top_holes.push(at_z(&boss, chamfer_z));

    // A pin (R4, 10 mm high).
    let pin_centre = [-10.0 * MM, -40.0 * MM];
    let pin = scaled(circle([-10.0, -40.0], 4.0, 40, 0.0));
    wall(
        &mut b,
        &at_z(&pin, chamfer_z),
        &at_z(&pin, 22.0 * MM),
        3,
        away_from(pin_centre),
    );
    b.face(&at_z(&pin, 22.0 * MM), &[], &Vector3::z())?;
    top_holes.push(at_z(&pin, chamfer_z));

    // A block turned 15 degrees about z, its top inclined 20 degrees along the block's long axis:
    // neither face is aligned with the plate's axes.
    let yaw = 15f64.to_radians();
    let block_centre = [-38.0 * MM, 5.0 * MM];
    let block = rotate_2d(
        &scaled(rounded_rect([-38.0, 5.0], [50.0, 36.0], 5.0, 10, 5.0)),
        block_centre,
        yaw,
    );
    let slope = 20f64.to_radians().tan();
    let (axis_x, axis_y) = (yaw.cos(), yaw.sin());
    let top_z = |p: &[f64; 2]| {
        34.0 * MM + slope * ((p[0] - block_centre[0]) * axis_x + (p[1] - block_centre[1]) * axis_y)
    };
    let block_top: Vec<Point3<f64>> = block
        .iter()
        .map(|p| Point3::new(p[0], p[1], top_z(p)))
        .collect();
    wall(
        &mut b,
        &at_z(&block, chamfer_z),
        &block_top,
        4,
        away_from(block_centre),
    );
    let top_normal = Vector3::new(-slope * axis_x, -slope * axis_y, 1.0).normalize();
    b.face(&block_top, &[], &top_normal)?;
    top_holes.push(at_z(&block, chamfer_z));

    b.face(&at_z(&inset, chamfer_z), &top_holes, &Vector3::z())?;
    b.finish()
}

/// One round hole through a flat flange of the bracket: centre in the face's (along, across)
/// coordinates and radius, mm.
struct FlangeHole {
    along: f64,
    y: f64,
    radius: f64,
}

/// A sheet-metal L bracket: 2.5 mm sheet, a 90-degree bend with a 3 mm inner and 5.5 mm outer
/// radius, an 80 mm base flange with two 6.6 mm holes and a 60 mm upright flange with a 6.6 mm
/// and a 4.5 mm hole, 50 mm wide. Closed and outward-oriented; about 10k triangles (the bend
/// and the flats are split every 1.25 mm across the width, as a fine CAD export would be).
pub fn thin_wall_bracket() -> Result<Mesh, MeshError> {
    let (t, ri, length, height, width) = (2.5, 3.0, 80.0, 60.0, 50.0);
    let ro = ri + t;
    let (bend_segments, rows, step) = (48, 40, 4.0);
    let ys: Vec<f64> = (0..=rows)
        .map(|j| width * j as f64 / rows as f64 * MM)
        .collect();
    let line = |from: f64, to: f64| -> Vec<f64> {
        let pieces = ((to - from).abs() / step).ceil() as usize;
        (0..=pieces)
            .map(|k| from + (to - from) * k as f64 / pieces as f64)
            .collect()
    };
    let arc = |radius: f64, from_deg: f64, to_deg: f64| -> Vec<[f64; 2]> {
        (0..=bend_segments)
            .map(|k| {
                let angle =
                    (from_deg + (to_deg - from_deg) * k as f64 / bend_segments as f64).to_radians();
                [ro + radius * angle.cos(), ro + radius * angle.sin()]
            })
            .collect()
    };
    // The profile in the (x, z) plane, walked once round; each run is one face of the sheet.
    let runs: Vec<Vec<[f64; 2]>> = vec![
        line(ro, length).into_iter().map(|x| [x, 0.0]).collect(), // base, underside
        vec![[length, 0.0], [length, t]],                         // base end
        line(length, ro).into_iter().map(|x| [x, t]).collect(),   // base, top
        arc(ri, 270.0, 180.0),                                    // bend, inside
        line(ro, height).into_iter().map(|z| [t, z]).collect(),   // upright, inside
        vec![[t, height], [0.0, height]],                         // upright end
        line(height, ro).into_iter().map(|z| [0.0, z]).collect(), // upright, outside
        arc(ro, 180.0, 270.0),                                    // bend, outside
    ];
    let to_3d = |p: [f64; 2], y: f64| Point3::new(p[0] * MM, y, p[1] * MM);
    let mut b = Builder::new();
    // Outward side of each run (the bend's runs point to or from the bend axis instead).
    let outward = [
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::x(),
        Vector3::z(),
        Vector3::zeros(), // bend inside: towards the bend axis, set below
        Vector3::x(),
        Vector3::z(),
        -Vector3::x(),
        Vector3::zeros(), // bend outside: away from the bend axis
    ];
    let base_holes = [
        FlangeHole {
            along: 52.0,
            y: 14.0,
            radius: 3.3,
        },
        FlangeHole {
            along: 52.0,
            y: 36.0,
            radius: 3.3,
        },
    ];
    let upright_holes = [
        FlangeHole {
            along: 40.0,
            y: 17.0,
            radius: 3.3,
        },
        FlangeHole {
            along: 30.0,
            y: 37.0,
            radius: 2.25,
        },
    ];
    let bend_axis = |p: &Point3<f64>| Vector3::new(p.x - ro * MM, 0.0, p.z - ro * MM);
    for (k, run) in runs.iter().enumerate() {
        let holes: &[FlangeHole] = match k {
            0 | 2 => &base_holes,
            4 | 6 => &upright_holes,
            _ => &[],
        };
        if matches!(k, 0 | 2 | 4 | 6) {
            // A flat with holes: one planar face whose border carries every row's vertex.
            let mut border: Vec<Point3<f64>> = run.iter().map(|&p| to_3d(p, 0.0)).collect();
            let last = run[run.len() - 1];
            border.extend(ys[1..rows].iter().map(|&y| to_3d(last, y)));
            border.extend(run.iter().rev().map(|&p| to_3d(p, ys[rows])));
            border.extend(ys[1..rows].iter().rev().map(|&y| to_3d(run[0], y)));
            let hole_loops: Vec<Vec<Point3<f64>>> =
                holes.iter().map(|h| flange_hole_loop(k, h, t)).collect();
            b.face(&border, &hole_loops, &outward[k])?;
            continue;
        }
        for pair in run.windows(2) {
            let a: Vec<Point3<f64>> = ys.iter().map(|&y| to_3d(pair[0], y)).collect();
            let c: Vec<Point3<f64>> = ys.iter().map(|&y| to_3d(pair[1], y)).collect();
            match k {
                3 => b.strip(&a, &c, false, |p| -bend_axis(p)),
                7 => b.strip(&a, &c, false, bend_axis),
                _ => b.strip(&a, &c, false, |_| outward[k]),
            }
        }
    }
    // Hole walls through the sheet.
    for (k_outer, k_inner, holes) in [(0, 2, &base_holes), (6, 4, &upright_holes)] {
        for h in holes.iter() {
            let outer = flange_hole_loop(k_outer, h, t);
            let inner = flange_hole_loop(k_inner, h, t);
            let centre = Point3::from(
                outer.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / outer.len() as f64,
            );
            b.strip(&outer, &inner, true, move |p| {
                let mut d = centre - p;
                if k_outer == 0 {
                    d.z = 0.0;
                } else {
                    d.x = 0.0;
                }
                d
            });
        }
    }
    // The two end caps: the whole profile at y = 0 and y = width.
    let mut profile: Vec<[f64; 2]> = Vec::new();
    for run in &runs {
        profile.extend_from_slice(&run[..run.len() - 1]);
    }
    let cap = |y: f64| profile.iter().map(|&p| to_3d(p, y)).collect::<Vec<_>>();
    b.face(&cap(0.0), &[], &-Vector3::y())?;
    b.face(&cap(ys[rows]), &[], &Vector3::y())?;
    b.finish()
}

/// The loop of a bracket hole on flat run `k` (0/2 base underside/top, 4/6 upright inside/
/// outside), 40 segments.
fn flange_hole_loop(k: usize, hole: &FlangeHole, thickness: f64) -> Vec<Point3<f64>> {
    circle([hole.along, hole.y], hole.radius, 40, 0.0)
        .into_iter()
        .map(|[along, y]| match k {
            0 => Point3::new(along * MM, y * MM, 0.0),
            2 => Point3::new(along * MM, y * MM, thickness * MM),
            4 => Point3::new(thickness * MM, y * MM, along * MM),
            _ => Point3::new(0.0, y * MM, along * MM),
        })
        .collect()
}

/// A housing cover as a CAD surface export often arrives: one skin, open at the bottom, with a
/// round 20 mm opening in its top. 120 x 80 x 40 mm, vertical corners R15, a R10 fillet round
/// the top edge. Not watertight (distances to it are unsigned); outward-oriented, so face
/// normals point away from the housing.
pub fn open_shell() -> Result<Mesh, MeshError> {
    let (size, corner, fillet, height) = ([120.0, 80.0], 15.0, 10.0, 40.0);
    let ring = |inset: f64, z: f64| {
        at_z(
            &scaled(rounded_rect(
                [0.0, 0.0],
                [size[0] - 2.0 * inset, size[1] - 2.0 * inset],
                corner - inset,
                16,
                5.0,
            )),
            z * MM,
        )
    };
    let mut b = Builder::new();
    let side_top = height - fillet;
    wall(
        &mut b,
        &ring(0.0, 0.0),
        &ring(0.0, side_top),
        10,
        away_from([0.0, 0.0]),
    );
    let steps = 12;
    let mut lower = ring(0.0, side_top);
    for k in 1..=steps {
        let angle = k as f64 / steps as f64 * std::f64::consts::FRAC_PI_2;
        let upper = ring(
            fillet * (1.0 - angle.cos()),
            side_top + fillet * angle.sin(),
        );
        b.strip(&lower, &upper, true, |p| {
            Vector3::new(p.x, p.y, p.x.hypot(p.y))
        });
        lower = upper;
    }
    let opening = at_z(&scaled(circle([25.0, 0.0], 10.0, 48, 0.0)), height * MM);
    b.face(&lower, &[opening], &Vector3::z())?;
    b.finish()
}

/// A turned flanged shaft, axis z, 120 mm long: a 30 mm shaft with 1 mm end chamfers, a 90 mm
/// flange 12 mm thick with six 9 mm bolt holes on a 64 mm circle (six-fold symmetric), a 40 mm
/// shoulder, and a 3 mm deep key flat 45 mm long on the shaft: the flat is the only feature that
/// breaks the symmetry, the near-ambiguity a real turned part presents. 128 segments round.
pub fn turned_part() -> Result<Mesh, MeshError> {
    let segments = 128;
    let ring =
        |radius: f64, z: f64| at_z(&scaled(circle([0.0, 0.0], radius, segments, 0.0)), z * MM);
    let out = away_from([0.0, 0.0]);
    let mut b = Builder::new();
    // Lower shaft end: chamfer, then the shaft up to the flange.
    b.face(&ring(14.0, 0.0), &[], &-Vector3::z())?;
    b.strip(&ring(14.0, 0.0), &ring(15.0, 1.0), true, |p| {
        Vector3::new(p.x, p.y, -0.01)
    });
    wall(&mut b, &ring(15.0, 1.0), &ring(15.0, 20.0), 10, out);
    // Flange with bolt holes.
    let bolt = |k: usize, z: f64| {
        let angle = (30.0 + 60.0 * k as f64).to_radians();
        let c = [32.0 * angle.cos(), 32.0 * angle.sin()];
        at_z(&scaled(circle(c, 4.5, 32, 0.0)), z * MM)
    };
    let mut under: Vec<Vec<Point3<f64>>> = vec![ring(15.0, 20.0)];
    let mut over: Vec<Vec<Point3<f64>>> = vec![ring(20.0, 32.0)];
    for k in 0..6 {
        under.push(bolt(k, 20.0));
        over.push(bolt(k, 32.0));
        let lower = bolt(k, 20.0);
        let c = Point3::from(
            lower.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / lower.len() as f64,
        );
        wall(&mut b, &lower, &bolt(k, 32.0), 3, towards([c.x, c.y]));
    }
    b.face(&ring(45.0, 20.0), &under, &-Vector3::z())?;
    wall(&mut b, &ring(45.0, 20.0), &ring(45.0, 32.0), 4, out);
    b.face(&ring(45.0, 32.0), &over, &Vector3::z())?;
    // Shoulder.
    wall(&mut b, &ring(20.0, 32.0), &ring(20.0, 40.0), 3, out);
    b.face(&ring(20.0, 40.0), &[ring(15.0, 40.0)], &Vector3::z())?;
    // Upper shaft with the key flat: vertices of the rings between 60 and 105 mm are pressed
    // onto the plane x = 12 mm; the rings just outside make a short run-out, as a side mill
    // leaves.
    let flat_x = 12.0 * MM;
    let mut zs: Vec<f64> = (0..=26).map(|k| 40.0 + 3.0 * k as f64).collect();
    zs.retain(|&z| z < 119.0);
    zs.extend([59.5, 60.0, 105.0, 105.5, 119.0]);
    zs.sort_by(f64::total_cmp);
    zs.dedup();
    let shaft_ring = |z: f64| {
        let mut r = ring(15.0, z);
        if (60.0..=105.0).contains(&z) {
            for p in &mut r {
                p.x = p.x.min(flat_x);
            }
        }
        r
    };
    for pair in zs.windows(2) {
        b.strip(&shaft_ring(pair[0]), &shaft_ring(pair[1]), true, out);
    }
    b.strip(&ring(15.0, 119.0), &ring(14.0, 120.0), true, |p| {
        Vector3::new(p.x, p.y, 0.01)
    });
    b.face(&ring(14.0, 120.0), &[], &Vector3::z())?;
    b.finish()
}

/// Every corpus part with its name, in a fixed order.
pub fn all_parts() -> Result<Vec<(&'static str, Mesh)>, MeshError> {
    Ok(vec![
        ("fixture_plate", fixture_plate()?),
        ("thin_wall_bracket", thin_wall_bracket()?),
        ("open_shell", open_shell()?),
        ("turned_part", turned_part()?),
    ])
}

/// A public robot-link mesh (e.g. the ABB IRB 1600 meshes of ROS-Industrial, kept outside the
/// repository) read from `path` and scaled by `unit_scale` (0.001 for files in mm). `None` when
/// no path is given: nothing in the corpus requires such a file.
pub fn robot_link_mesh(path: Option<&Path>, unit_scale: f64) -> Result<Option<Mesh>, CorpusError> {
    let Some(path) = path else {
        return Ok(None);
    };
    let soup = crate::io::read_mesh(path, unit_scale)?;
    Ok(Some(Mesh::new(&soup.vertices, &soup.triangles)?))
}
