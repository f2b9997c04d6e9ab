//! Map-file tracks (ROS map_server YAML and a PGM or PNG): walls where the occupied pixels are,
//! a centre line from a CSV or traced, and clear errors on bad files.

use super::*;
use std::path::Path;

const RES: f64 = 0.1;

/// A 60 x 40 pixel ring: a 2-pixel border and a central island, free between them (1.0 m
/// wide lanes), with a notch cut into the island so that the walls are not all boxes.
fn ring() -> Vec<Vec<u8>> {
    let (w, h) = (60, 40);
    (0..h)
        .map(|r| {
            (0..w)
                .map(|c| {
                    let border = r < 2 || r >= h - 2 || c < 2 || c >= w - 2;
                    let island = (12..28).contains(&r)
                        && (12..48).contains(&c)
                        && !((12..16).contains(&r) && (20..23).contains(&c));
                    if border || island { 0 } else { 254 }
                })
                .collect()
        })
        .collect()
}

/// Write `px` (top row first) as `map.pgm` and `map.yaml` with `origin`; `extra` lines join the
/// YAML; `csv`, when given, is written beside it as `map.csv`.
fn write_map(dir: &Path, px: &[Vec<u8>], origin: [f64; 3], extra: &str, csv: Option<&str>) -> PathBuf {
    let (w, h) = (px[0].len(), px.len());
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm.extend(px.iter().flatten());
    std::fs::write(dir.join("map.pgm"), pgm).unwrap();
    let yaml = dir.join("map.yaml");
    std::fs::write(
        &yaml,
        format!(
            "image: map.pgm\nresolution: {RES}\norigin: [{}, {}, {}]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}",
            origin[0], origin[1], origin[2]
        ),
    )
    .unwrap();
    if let Some(c) = csv {
        std::fs::write(dir.join("map.csv"), c).unwrap();
    }
    yaml
}

/// The world point of pixel (column, row from the top) + (u, v) pixels, by map_server's
/// rule: the origin is the pose of the bottom-left corner of the image.
fn world(origin: [f64; 3], h: usize, c: f64, r_top: f64) -> [f64; 2] {
    let (lx, ly) = (c * RES, (h as f64 - r_top) * RES);
    let (s, co) = origin[2].sin_cos();
    [origin[0] + co * lx - s * ly, origin[1] + s * lx + co * ly]
}

/// The ring's lane centre line (a rectangle through the middle of each lane), in the world.
fn ring_csv(origin: [f64; 3]) -> String {
    let corners = [(7.0, 33.0), (53.0, 33.0), (53.0, 7.0), (7.0, 7.0)];
    let mut out = String::from("# x_m, y_m\n");
    for (c, r) in corners {
        let [x, y] = world(origin, 40, c, r);
        out += &format!("{x}, {y}\n");
    }
    out
}

/// Distance from `p` to the wall box (0 inside), and how deep inside it `p` lies (0 outside).
fn to_box(wall: &[f32; 5], p: [f64; 2]) -> (f64, f64) {
    let (s, c) = (wall[4] as f64).sin_cos();
    let (dx, dy) = (p[0] - wall[0] as f64, p[1] - wall[1] as f64);
    let (lx, ly) = ((c * dx + s * dy).abs(), (-s * dx + c * dy).abs());
    let (ex, ey) = ((lx - wall[2] as f64).max(0.0), (ly - wall[3] as f64).max(0.0));
    let depth = (wall[2] as f64 - lx).min(wall[3] as f64 - ly).max(0.0);
    ((ex * ex + ey * ey).sqrt(), depth)
}

/// For an origin at zero, shifted, and shifted and rotated: a wall face runs within
/// `SIMPLIFY_PX` of the middle of every edge between a free pixel and one that is not, no
/// free pixel's centre lies deeper in a wall than the faces may stray past it, and the walls
/// are far fewer than those edges.
#[test]
fn a_map_file_round_trips_to_walls_at_its_pixels_for_any_origin() {
    let px = ring();
    let (w, h) = (px[0].len(), px.len());
    let free =
        |c: i64, r: i64| c >= 0 && r >= 0 && (c as usize) < w && (r as usize) < h && px[r as usize][c as usize] == 254;
    for origin in [[0.0, 0.0, 0.0], [-3.5, 2.25, 0.0], [1.5, -4.0, 0.7], [-2.0, -1.0, -2.5]] {
        let d = tmpdir("map-round-trip");
        let yaml = write_map(d.path(), &px, origin, "", Some(&ring_csv(origin)));
        let t = MapTrack::load(&yaml).unwrap();
        assert_eq!(t.centreline_source, "csv");
        let mut edges = 0;
        for r in 0..h as i64 {
            for c in 0..w as i64 {
                if !free(c, r) {
                    continue;
                }
                let p = world(origin, h, c as f64 + 0.5, r as f64 + 0.5);
                let depth = t.walls.iter().map(|b| to_box(b, p).1).fold(0.0, f64::max);
                let bound = (agvrl_sim::scene::SIMPLIFY_PX - 0.5) * RES + 1e-4;
                assert!(
                    depth <= bound,
                    "origin {origin:?}: free pixel ({c}, {r}) {depth} m deep in a wall"
                );
                // Each side towards a pixel that is not free: the middle of that edge.
                for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    if free(c + dc, r + dr) {
                        continue;
                    }
                    edges += 1;
                    let m = world(
                        origin,
                        h,
                        c as f64 + 0.5 + 0.5 * dc as f64,
                        r as f64 + 0.5 + 0.5 * dr as f64,
                    );
                    let near = t.walls.iter().map(|b| to_box(b, m).0).fold(f64::INFINITY, f64::min);
                    assert!(
                        near <= agvrl_sim::scene::SIMPLIFY_PX * RES + 1e-4,
                        "origin {origin:?}: edge of pixel ({c}, {r}) towards ({dc}, {dr}) is {near} m from a wall"
                    );
                }
            }
        }
        assert!(t.walls.len() * 10 < edges, "{} walls for {edges} edges", t.walls.len());
    }
}

/// The same map as a PNG gives the same walls as the PGM.
#[test]
fn a_png_map_gives_the_walls_of_the_same_pgm() {
    let px = ring();
    let origin = [1.0, 2.0, 0.3];
    let d = tmpdir("map-png");
    let yaml = write_map(d.path(), &px, origin, "", Some(&ring_csv(origin)));
    let from_pgm = MapTrack::load(&yaml).unwrap();
    let img = image::GrayImage::from_raw(60, 40, px.concat()).unwrap();
    img.save(d.path().join("map.png")).unwrap();
    let text = std::fs::read_to_string(&yaml).unwrap().replace("map.pgm", "map.png");
    std::fs::write(&yaml, text).unwrap();
    let from_png = MapTrack::load(&yaml).unwrap();
    assert_eq!(from_png.walls, from_pgm.walls);
    assert_eq!(from_png.centreline, from_pgm.centreline);
}

/// A LiDAR ray across the lane meets the island's face at the analytic distance.
#[test]
fn the_lidar_meets_a_map_wall_at_the_analytic_distance() {
    let px = ring();
    let origin = [-3.0, -2.0, 0.0];
    let d = tmpdir("map-lidar");
    let yaml = write_map(d.path(), &px, origin, "", Some(&ring_csv(origin)));
    let t = MapTrack::load(&yaml).unwrap();
    let mut s = sim(SceneSource::Map(Box::new(t)), DynamicsMode::Raycast);
    // In the bottom lane (image rows 28..38, world y from origin + 0.2 to + 1.2), facing the
    // island (+y).
    let [x, y] = world(origin, 40, 30.0, 35.0);
    s.reset(PlanarPose {
        x_m: x as f32,
        y_m: y as f32,
        yaw_rad: std::f32::consts::FRAC_PI_2,
    })
    .unwrap();
    let scan = s.lidar_scan(0);
    // The island's bottom face: image row 28 from the top, y = origin + (40 - 28) * RES.
    let face_y = origin[1] + 12.0 * RES;
    let o = scan.origin_w;
    let mut checked = 0;
    for (i, &r) in scan.ranges.iter().enumerate() {
        let a = scan.angle_min + i as f32 * scan.angle_increment;
        // Rays within 30 degrees of straight ahead meet the face near x = 30 pixels.
        if a.abs() > 30f32.to_radians() {
            continue;
        }
        let expect = (face_y - o[1] as f64) / (a as f64).cos();
        assert!(
            (r as f64 - expect).abs() < 2e-3,
            "ray {i} at {a} rad: {r} m, face at {expect} m"
        );
        checked += 1;
    }
    assert!(checked > 10, "{checked} rays checked");
}

/// Without a CSV, the centre line traced through the free space of the shipped bean keeps
/// within 5 cm of its drawn centre line (the CSV the generator wrote), and has its length.
#[test]
fn a_traced_centre_line_follows_the_drawn_one() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks");
    let drawn = MapTrack::load(&root.join("bean.yaml")).unwrap();
    let d = tmpdir("map-trace");
    for f in ["bean.yaml", "bean.pgm"] {
        std::fs::copy(root.join(f), d.path().join(f)).unwrap();
    }
    let traced = MapTrack::load(&d.path().join("bean.yaml")).unwrap();
    assert_eq!(
        (drawn.centreline_source.as_str(), traced.centreline_source.as_str()),
        ("csv", "traced")
    );
    assert_eq!(traced.walls, drawn.walls);
    let (ld, lt) = (drawn.lap_length_m(), traced.lap_length_m());
    assert!((lt - ld).abs() < 0.02 * ld, "traced {lt} m, drawn {ld} m");
    let worst = traced
        .centreline
        .iter()
        .map(|p| {
            drawn
                .centreline
                .iter()
                .map(|q| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
                .fold(f32::INFINITY, f32::min)
        })
        .fold(0.0f32, f32::max);
    // The drawn points are 0.1 m apart: nearest-point distance adds at most 5 cm.
    assert!(worst < 0.10, "a traced point lies {worst} m from the drawn centre line");
}

fn load_err(yaml: &Path) -> String {
    match MapTrack::load(yaml) {
        Ok(_) => panic!("{} loaded", yaml.display()),
        Err(e) => e.to_string(),
    }
}

/// Bad map files name the file and what is wrong.
#[test]
fn bad_map_files_give_clear_errors() {
    let px = ring();
    let o = [0.0, 0.0, 0.0];
    let csv = ring_csv(o);
    let d = tmpdir("map-errors");
    let yaml = write_map(d.path(), &px, o, "", Some(&csv));
    // The image is missing.
    std::fs::remove_file(d.path().join("map.pgm")).unwrap();
    let e = load_err(&yaml);
    assert!(e.contains("map.pgm") && e.contains("No such file"), "{e}");
    // Fewer pixels than the header says.
    let yaml = write_map(d.path(), &px, o, "", Some(&csv));
    let mut short = b"P5\n60 40\n255\n".to_vec();
    short.extend(&px.concat()[..1000]);
    std::fs::write(d.path().join("map.pgm"), short).unwrap();
    let e = load_err(&yaml);
    assert!(e.contains("map.pgm") && e.contains("bad image"), "{e}");
    // A misspelt threshold.
    let yaml = write_map(d.path(), &px, o, "occupied_threshold: 0.5\n", Some(&csv));
    let e = load_err(&yaml);
    assert!(
        e.contains("map.yaml") && e.contains("unknown field `occupied_threshold`"),
        "{e}"
    );
    // A required key missing.
    std::fs::write(
        &yaml,
        "image: map.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nfree_thresh: 0.2\n",
    )
    .unwrap();
    let e = load_err(&yaml);
    assert!(e.contains("missing field `occupied_thresh`"), "{e}");
    // Thresholds the wrong way round.
    std::fs::write(
        &yaml,
        "image: map.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.2\nfree_thresh: 0.6\n",
    )
    .unwrap();
    let e = load_err(&yaml);
    assert!(e.contains("free_thresh < occupied_thresh"), "{e}");
    // A resolution of zero.
    std::fs::write(
        &yaml,
        "image: map.pgm\nresolution: 0\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
    )
    .unwrap();
    assert!(load_err(&yaml).contains("resolution must be in (0, 1]"));
    // A centre-line point on a wall.
    let yaml = write_map(d.path(), &px, o, "", Some("0.7, 0.7\n0.05, 0.05\n5.3, 3.3\n"));
    let e = load_err(&yaml);
    assert!(
        e.contains("map.csv") && e.contains("point 2") && e.contains("not in the map's free space"),
        "{e}"
    );
    // A centre-line row that is not x, y.
    let yaml = write_map(d.path(), &px, o, "", Some("x, y\n0.7, 0.7\n5.3, three\n"));
    let e = load_err(&yaml);
    assert!(e.contains("line 3"), "{e}");
    // No CSV, and the map's origin lies in the border: nowhere to start a trace.
    std::fs::remove_file(d.path().join("map.csv")).unwrap();
    let e = load_err(&yaml);
    assert!(e.contains("not in free space") && e.contains("NAME.csv"), "{e}");
}
