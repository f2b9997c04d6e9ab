//! Generated circuits: closed and drivable, spread over their settings, walled on both edges, the
//! same per seed, written as map files that load back, settings validated, a circuit scene built
//! from its seed, dead-end pockets walled round beside an unchanged track.

use super::*;
use agvrl_sim::scene::write_map;
use std::f64::consts::PI;

/// Training-half seeds (the top bit clear).
const SEEDS: std::ops::Range<u64> = 0..200;
/// What the generator promises beyond the width: stretches of track a width and this apart,
/// corners at least half of it wider than half the width.
const GAP_M: f64 = 0.5;

fn line(t: &MapTrack) -> Vec<[f64; 2]> {
    t.centreline.iter().map(|p| [p[0] as f64, p[1] as f64]).collect()
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Radius of the circle through three points (infinite when they are collinear).
fn circumradius(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    dist(a, b) * dist(b, c) * dist(c, a) / (2.0 * cross.abs())
}

/// The smallest radius of the circle through three consecutive points of the closed line.
fn min_radius(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| circumradius(p[(i + n - 1) % n], p[i], p[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

/// The largest turn, degrees, of a bend whose consecutive points all lie on circles of at
/// most `r_max`: a hairpin of that radius shows as one turning at least its arc less a
/// segment.
fn sharpest_bend_deg(p: &[[f64; 2]], r_max: f64) -> f64 {
    let n = p.len();
    let turn = |i: usize| {
        let (a, b, c) = (p[(i + n - 1) % n], p[i], p[(i + 1) % n]);
        let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
        (u[0] * v[1] - u[1] * v[0]).atan2(u[0] * v[0] + u[1] * v[1])
    };
    let (mut best, mut run) = (0.0f64, 0.0f64);
    for i in 0..2 * n {
        let k = i % n;
        let t = turn(k);
        if circumradius(p[(k + n - 1) % n], p[k], p[(k + 1) % n]) <= r_max && (run == 0.0 || run.signum() == t.signum())
        {
            run += t;
        } else {
            run = 0.0;
        }
        best = best.max(run.abs());
    }
    best.to_degrees()
}

/// The closed line with points at most `step` apart, each with its distance along the lap.
fn densify(p: &[[f64; 2]], step: f64) -> (Vec<([f64; 2], f64)>, f64) {
    let mut out = Vec::new();
    let mut s = 0.0;
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        let l = dist(a, b);
        let k = (l / step).ceil().max(1.0) as usize;
        for j in 0..k {
            let u = j as f64 / k as f64;
            out.push(([a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])], s + u * l));
        }
        s += l;
    }
    (out, s)
}

/// The closest pair of points more than `along` apart along the lap (the shorter way round),
/// found by a sweep over x: (distance, the two points).
fn closest_far_pair(p: &[[f64; 2]], along: f64, reach: f64) -> (f64, [f64; 2], [f64; 2]) {
    let (pts, lap) = densify(p, 0.25);
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by(|&a, &b| pts[a].0[0].total_cmp(&pts[b].0[0]));
    let mut best = (f64::INFINITY, [0.0; 2], [0.0; 2]);
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if pts[j].0[0] - pts[i].0[0] > reach {
                break;
            }
            let ds = (pts[i].1 - pts[j].1).abs();
            let d = dist(pts[i].0, pts[j].0);
            if ds.min(lap - ds) > along && d < best.0 {
                best = (d, pts[i].0, pts[j].0);
            }
        }
    }
    best
}

/// Distance from `p` to the closed line.
fn to_line(p: [f64; 2], line: &[[f64; 2]]) -> f64 {
    (0..line.len())
        .map(|i| {
            let (a, b) = (line[i], line[(i + 1) % line.len()]);
            let ab = [b[0] - a[0], b[1] - a[1]];
            let u = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1])).clamp(0.0, 1.0);
            dist(p, [a[0] + u * ab[0], a[1] + u * ab[1]])
        })
        .fold(f64::INFINITY, f64::min)
}

/// Distance from `p` to a wall box (0 inside).
fn to_box(wall: &[f32; 5], p: [f64; 2]) -> f64 {
    let (s, c) = (wall[4] as f64).sin_cos();
    let (dx, dy) = (p[0] - wall[0] as f64, p[1] - wall[1] as f64);
    let (lx, ly) = ((c * dx + s * dy).abs(), (-s * dx + c * dy).abs());
    ((lx - wall[2] as f64).max(0.0)).hypot((ly - wall[3] as f64).max(0.0))
}

/// The corners of a rectangle: centre, half length, half width, yaw.
fn corners(c: [f64; 2], hl: f64, hw: f64, yaw: f64) -> [[f64; 2]; 4] {
    let (s, co) = yaw.sin_cos();
    [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
        .map(|(a, b)| [c[0] + a * hl * co - b * hw * s, c[1] + a * hl * s + b * hw * co])
}

/// Whether two rectangles (as corners) overlap: no separating axis among their edges.
fn overlap(a: &[[f64; 2]; 4], b: &[[f64; 2]; 4]) -> bool {
    let axes = [(a[0], a[1]), (a[0], a[3]), (b[0], b[1]), (b[0], b[3])].map(|(p, q)| [q[0] - p[0], q[1] - p[1]]);
    axes.into_iter().all(|ax| {
        let span = |r: &[[f64; 2]; 4]| {
            let d = r.map(|p| p[0] * ax[0] + p[1] * ax[1]);
            (
                d.iter().copied().fold(f64::INFINITY, f64::min),
                d.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let ((a0, a1), (b0, b1)) = (span(a), span(b));
        a1 > b0 && b1 > a0
    })
}

/// Over 200 seeds: the centre line is closed with points at most 1 m apart, the lap and the
/// width lie in their ranges, no corner is tighter than allowed (measured from the points),
/// no two stretches of track come closer than a width and half a metre, and a car at the
/// start, heading along the line, touches no wall.
#[test]
fn generated_circuits_are_closed_and_drivable() {
    let s = CircuitSettings::default();
    for seed in SEEDS {
        let (t, info) = MapTrack::generated(seed, &s).unwrap();
        t.validate().unwrap();
        assert_eq!(
            (t.name.as_str(), t.centreline_source.as_str(), t.resolution_m),
            (format!("circuit-{seed}").as_str(), "generated", 0.05)
        );
        let p = line(&t);
        let n = p.len();
        let step = (0..n).map(|i| dist(p[i], p[(i + 1) % n])).fold(0.0, f64::max);
        assert!(step <= 1.0 + 1e-4, "seed {seed}: points {step} m apart");
        let lap = t.lap_length_m();
        assert_eq!(info.length_m, lap);
        assert!((50.0 * 0.98..=500.0 * 1.02).contains(&lap), "seed {seed}: lap {lap} m");
        let w = info.width_m as f64;
        assert!((1.5..=3.5).contains(&w), "seed {seed}: width {w} m");
        let floor = (1.0f64).max(0.5 * (w + GAP_M));
        let r = min_radius(&p);
        assert!(r >= 0.97 * floor, "seed {seed}: a corner of {r} m, under {floor} m");
        assert!(info.min_radius_m as f64 >= floor - 1e-4 && r >= 0.97 * info.min_radius_m as f64);
        let c = w + GAP_M;
        let (d, a, b) = closest_far_pair(&p, PI * c, c);
        assert!(
            d >= c - 1e-3,
            "seed {seed}: stretches at {a:?} and {b:?} are {d} m apart, under {c} m"
        );
        let yaw = (p[1][1] - p[0][1]).atan2(p[1][0] - p[0][0]);
        let car = corners(p[0], 0.275, 0.175, yaw);
        for wall in &t.walls {
            let wb = corners(
                [wall[0] as f64, wall[1] as f64],
                wall[2] as f64,
                wall[3] as f64,
                wall[4] as f64,
            );
            assert!(
                !overlap(&car, &wb),
                "seed {seed}: the car at the start touches {wall:?}"
            );
        }
    }
}

/// With `wall_gap_m = 0.2` the walls of two stretches may stand back to back: hairpins turn
/// round a tip 0.1 m wider than the half width, tighter than the default gap allows, while no
/// two stretches come closer than the width and 0.2 m (the independent checks of the
/// closed-and-drivable test).
#[test]
fn thin_walls_let_hairpins_turn_round_a_thin_tip_and_stretches_come_no_closer() {
    let s = CircuitSettings {
        wall_gap_m: 0.2,
        min_radius_m: 0.6,
        tight_share: 1.0,
        ..CircuitSettings::default()
    };
    let mut thin_tips = 0;
    for seed in 0..60 {
        let (t, info) = MapTrack::generated(seed, &s).unwrap();
        t.validate().unwrap();
        let p = line(&t);
        let w = info.width_m as f64;
        let floor = (0.6f64).max(0.5 * (w + 0.2));
        let r = min_radius(&p);
        assert!(r >= 0.97 * floor, "seed {seed}: a corner of {r} m, under {floor} m");
        let c = w + 0.2;
        let (d, a, b) = closest_far_pair(&p, PI * c, c);
        assert!(
            d >= c - 1e-3,
            "seed {seed}: stretches at {a:?} and {b:?} are {d} m apart, under {c} m"
        );
        thin_tips += usize::from(r < 0.97 * 0.5 * (w + GAP_M));
    }
    assert!(thin_tips >= 10, "{thin_tips} of 60 circuits turn round a thin tip");
}

/// Over 200 seeds the circuits cover their settings: at least 30 % with a corner of 1.5 m
/// or less and 30 % at most 2 m wide, hairpins on a fifth or more, both directions (as
/// the info says, by the line's signed area), and laps in every quarter of the range.
#[test]
fn circuits_spread_over_their_settings() {
    let s = CircuitSettings::default();
    let (mut tight, mut narrow, mut hairpin, mut clockwise) = (0, 0, 0, 0);
    let mut quarters = [0; 4];
    let (mut shortest, mut longest) = (f32::INFINITY, 0.0f32);
    for seed in SEEDS {
        let (t, info) = MapTrack::generated(seed, &s).unwrap();
        let p = line(&t);
        tight += (min_radius(&p) <= 1.5) as usize;
        narrow += (info.width_m <= 2.0) as usize;
        hairpin += (sharpest_bend_deg(&p, 1.5 * 1.01) >= 150.0 - 5.5) as usize;
        let area: f64 = (0..p.len())
            .map(|i| {
                let (a, b) = (p[i], p[(i + 1) % p.len()]);
                0.5 * (a[0] * b[1] - b[0] * a[1])
            })
            .sum();
        assert_eq!(
            info.clockwise,
            area < 0.0,
            "seed {seed}: clockwise {} but area {area}",
            info.clockwise
        );
        clockwise += info.clockwise as usize;
        quarters[(((info.length_m - 50.0) / 450.0 * 4.0) as usize).min(3)] += 1;
        shortest = shortest.min(info.length_m);
        longest = longest.max(info.length_m);
    }
    let n = SEEDS.count() as f64;
    let share = |k: usize| k as f64 / n;
    eprintln!(
        "over {n} circuits: corner <= 1.5 m {:.2}, width <= 2 m {:.2}, hairpin {:.2}, clockwise {:.2}, \
         laps {shortest:.1} to {longest:.1} m, by quarter {quarters:?}",
        share(tight),
        share(narrow),
        share(hairpin),
        share(clockwise)
    );
    assert!(share(tight) >= 0.3, "{tight} circuits with a corner of 1.5 m or less");
    assert!(share(narrow) >= 0.3, "{narrow} circuits at most 2 m wide");
    assert!(share(hairpin) >= 0.2, "{hairpin} circuits with a hairpin");
    assert!(
        (0.3..=0.7).contains(&share(clockwise)),
        "{clockwise} clockwise circuits"
    );
    assert!(
        quarters.iter().all(|&q| share(q) >= 0.15),
        "laps by quarter {quarters:?}"
    );
}

/// Every wall box stands just off the track, its face half the width from the centre line,
/// no centre-line point lies within half the width of a wall, and every stretch of both
/// edges has a wall at it (no gap a car could leave by).
#[test]
fn walls_line_both_edges_and_stand_off_the_track() {
    let s = CircuitSettings::default();
    for seed in 0..30 {
        let (t, info) = MapTrack::generated(seed, &s).unwrap();
        let p = line(&t);
        let hw = 0.5 * info.width_m as f64;
        for wall in &t.walls {
            let d = to_line([wall[0] as f64, wall[1] as f64], &p);
            let face = d - wall[3] as f64;
            // The line's chords cut a bend by up to 1 - cos(2.5 deg) of its radius, so an
            // inner wall may stand that share of the half width nearer to them.
            assert!(
                (hw * (1.0 - 1e-3) - 1e-4..=hw + 0.03).contains(&face),
                "seed {seed}: wall {wall:?} faces the track {face} m from the line, half the width is {hw}"
            );
        }
        for q in &p {
            let near = t.walls.iter().map(|w| to_box(w, *q)).fold(f64::INFINITY, f64::min);
            assert!(near >= hw - 1e-3, "seed {seed}: {q:?} is {near} m from a wall");
        }
        // The edges half way along each segment, both sides.
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            let l = dist(a, b);
            let nrm = [-(b[1] - a[1]) / l, (b[0] - a[0]) / l];
            for side in [-1.0, 1.0] {
                let e = [
                    0.5 * (a[0] + b[0]) + side * hw * nrm[0],
                    0.5 * (a[1] + b[1]) + side * hw * nrm[1],
                ];
                let near = t.walls.iter().map(|w| to_box(w, e)).fold(f64::INFINITY, f64::min);
                assert!(near <= 0.03, "seed {seed}: the edge at {e:?} is {near} m from any wall");
            }
        }
    }
}

/// A seed gives the same circuit every time; other seeds or settings give others.
#[test]
fn a_seed_gives_the_same_circuit_every_time() {
    let s = CircuitSettings::default();
    let (a, ia) = MapTrack::generated(42, &s).unwrap();
    let (b, ib) = MapTrack::generated(42, &s).unwrap();
    assert_eq!((&a, ia), (&b, ib));
    let (c, _) = MapTrack::generated(43, &s).unwrap();
    assert_ne!((&a.centreline, &a.crc32), (&c.centreline, &c.crc32));
    let wider = CircuitSettings {
        width_m: [2.5, 3.5],
        ..s
    };
    let (d, id) = MapTrack::generated(42, &wider).unwrap();
    assert_ne!(a.crc32, d.crc32);
    assert!(id.width_m >= 2.5);
}

/// A circuit written as map_server files loads back with `MapTrack::load`: the centre line
/// from the CSV is the written one, the lap agrees, and the walls traced from the image lie
/// within two pixels of the generated edges, with no edge left without a wall.
#[test]
fn a_written_circuit_loads_back_as_generated() {
    let s = CircuitSettings {
        length_m: [80.0, 160.0],
        ..Default::default()
    };
    for seed in [3, 7] {
        let (t, info) = MapTrack::generated(seed, &s).unwrap();
        let d = tmpdir("circuit-map");
        let yaml = write_map(&t, &info, d.path()).unwrap();
        assert_eq!(yaml, d.path().join(format!("circuit-{seed}.yaml")));
        let mut names: Vec<String> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["csv", "png", "yaml"].map(|e| format!("circuit-{seed}.{e}")));
        let back = MapTrack::load(&yaml).unwrap();
        assert_eq!(
            (back.centreline_source.as_str(), &back.centreline),
            ("csv", &t.centreline)
        );
        assert!((back.lap_length_m() / t.lap_length_m() - 1.0).abs() < 5e-3);
        assert_eq!(back.resolution_m, 0.05);
        let (p, hw, px) = (line(&t), 0.5 * info.width_m as f64, 0.05);
        for wall in &back.walls {
            let face = to_line([wall[0] as f64, wall[1] as f64], &p) - wall[3] as f64;
            assert!(
                (face - hw).abs() <= 2.0 * px,
                "seed {seed}: loaded wall {wall:?} faces the track {face} m from the line, not {hw}"
            );
        }
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            let l = dist(a, b);
            let nrm = [-(b[1] - a[1]) / l, (b[0] - a[0]) / l];
            for side in [-1.0, 1.0] {
                let e = [a[0] + side * hw * nrm[0], a[1] + side * hw * nrm[1]];
                let near = back.walls.iter().map(|w| to_box(w, e)).fold(f64::INFINITY, f64::min);
                assert!(
                    near <= 2.0 * px,
                    "seed {seed}: the edge at {e:?} is {near} m from a loaded wall"
                );
            }
        }
    }
}

/// Points of a pocket's floor (given as its corners: mouth outer, end outer, end inner, mouth
/// inner) at fractions `u` along it and `v` across it, from the outer side.
fn on_floor(q: &[[f32; 2]; 4], u: f64, v: f64) -> [f64; 2] {
    let q = q.map(|p| p.map(f64::from));
    std::array::from_fn(|a| q[0][a] + u * (q[1][a] - q[0][a]) + v * (q[3][a] - q[0][a]))
}

/// With `pocket_share = 1`, sharp corners get dead-end pockets and the track stays as drawn
/// without them (the same centre line, width and name but for the pockets' setting). Each
/// pocket's floor is open ground: no wall stands on it but along its inner side. Its outer
/// side, its end and its inner side are walled wherever they leave the track band, so a car
/// that drives in meets a wall. No wall stands within half the width of the centre line, and
/// the map written from the circuit holds the floors as free space.
#[test]
fn pockets_are_dead_ends_walled_round_beside_an_unchanged_track() {
    let plain = CircuitSettings::default();
    let with = CircuitSettings {
        pocket_share: 1.0,
        ..plain
    };
    let (mut pockets, mut hairpins) = (0, 0);
    for seed in 0..40 {
        let (t, info) = MapTrack::generated(seed, &with).unwrap();
        let (t0, info0) = MapTrack::generated(seed, &plain).unwrap();
        assert_eq!(
            (&t.centreline, info.width_m),
            (&t0.centreline, info0.width_m),
            "seed {seed}"
        );
        assert!(info0.pockets.is_empty() && t.crc32 != t0.crc32);
        let p = line(&t);
        let hw = 0.5 * info.width_m as f64;
        for q in &p {
            let near = t.walls.iter().map(|w| to_box(w, *q)).fold(f64::INFINITY, f64::min);
            assert!(near >= hw - 1e-3, "seed {seed}: {q:?} is {near} m from a wall");
        }
        pockets += info.pockets.len();
        hairpins += (!info.pockets.is_empty() && info.min_radius_m <= 1.5) as usize;
        for q in &info.pockets {
            let long = dist(on_floor(q, 0.0, 0.0), on_floor(q, 1.0, 0.0));
            let mid = on_floor(q, 0.5, 0.5);
            let near: Vec<&[f32; 5]> = (t.walls.iter())
                .filter(|w| dist([w[0] as f64, w[1] as f64], mid) < long + 2.0 * hw + w[2] as f64)
                .collect();
            let nearest_wall = |e: [f64; 2]| near.iter().map(|w| to_box(w, e)).fold(f64::INFINITY, f64::min);
            assert!(long > 1.0 + 2.0 * hw.min(1.0), "seed {seed}: a pocket {long} m long");
            let (nu, nv) = ((long / 0.05) as usize, (2.0 * hw / 0.05) as usize);
            for i in 1..nu {
                let u = i as f64 / nu as f64;
                // The floor, off its inner side's wall.
                for j in 1..nv {
                    let v = j as f64 / nv as f64;
                    if v * 2.0 * hw < 2.0 * hw - 0.12 {
                        let e = on_floor(q, u, v);
                        assert!(
                            nearest_wall(e) > 0.0,
                            "seed {seed}: a wall on the pocket's floor at {e:?}"
                        );
                    }
                }
                // Just beyond the outer side, and on the inner side: walled, or the track (the
                // centre line's chords cut the bend by a millimetre or two).
                for v in [-0.03 / (2.0 * hw), 1.0] {
                    let e = on_floor(q, u, v);
                    let on_track = to_line(e, &p) < hw + 0.01;
                    assert!(
                        on_track || nearest_wall(e) <= 0.01,
                        "seed {seed}: the pocket's side at {e:?} is open: {} m from the line, {} from a wall, half width {hw}",
                        to_line(e, &p),
                        nearest_wall(e)
                    );
                }
            }
            for j in 0..=nv {
                let e = on_floor(q, 1.0 + 0.03 / long, j as f64 / nv as f64);
                assert!(
                    nearest_wall(e) <= 0.01,
                    "seed {seed}: the pocket's end at {e:?} is open"
                );
            }
        }
        if seed < 2 && !info.pockets.is_empty() {
            let d = tmpdir("circuit-pockets");
            let back = MapTrack::load(&write_map(&t, &info, d.path()).unwrap()).unwrap();
            for q in &info.pockets {
                let e = on_floor(q, 0.6, 0.4);
                let near = back.walls.iter().map(|w| to_box(w, e)).fold(f64::INFINITY, f64::min);
                assert!(
                    near > 0.2,
                    "seed {seed}: the written map walls the pocket's floor at {e:?}"
                );
            }
        }
    }
    assert!(
        pockets >= 40 && hairpins >= 5,
        "{pockets} pockets, {hairpins} circuits with a tight corner"
    );
}

/// The defaults are the documented ranges; every out-of-range key is refused naming the
/// `circuit` table and the key, by `validate` and by the generator, and a TOML with an
/// unknown key does not parse.
#[test]
fn circuit_settings_default_to_the_documented_ranges_and_refuse_bad_keys() {
    let s = CircuitSettings::default();
    assert_eq!(
        (
            s.length_m,
            s.width_m,
            s.narrow_share,
            s.min_radius_m,
            s.tight_share,
            s.resolution_m,
            s.wall_gap_m
        ),
        ([50.0, 500.0], [1.5, 3.5], 0.4, 1.0, 0.5, 0.05, 0.5)
    );
    s.validate().unwrap();
    let bad = [
        (
            "length_m",
            CircuitSettings {
                length_m: [300.0, 200.0],
                ..s
            },
        ),
        (
            "length_m",
            CircuitSettings {
                length_m: [f32::NAN, 200.0],
                ..s
            },
        ),
        (
            "width_m",
            CircuitSettings {
                width_m: [0.2, 2.0],
                ..s
            },
        ),
        ("narrow_share", CircuitSettings { narrow_share: 1.5, ..s }),
        ("min_radius_m", CircuitSettings { min_radius_m: 0.0, ..s }),
        ("tight_share", CircuitSettings { tight_share: -0.1, ..s }),
        ("resolution_m", CircuitSettings { resolution_m: 0.0, ..s }),
        ("wall_gap_m", CircuitSettings { wall_gap_m: 0.1, ..s }),
        (
            "wall_gap_m",
            CircuitSettings {
                wall_gap_m: f32::NAN,
                ..s
            },
        ),
        // A 30 m lap cannot hold the corners of a 3.5 m wide track.
        (
            "length_m[0]",
            CircuitSettings {
                length_m: [30.0, 60.0],
                ..s
            },
        ),
    ];
    for (key, b) in bad {
        let e = b.validate().unwrap_err();
        assert_eq!(e.table, "circuit");
        assert!(e.message.contains(key), "'{}' does not name {key}", e.message);
        let e = MapTrack::generated(1, &b).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains("circuit-1"), "{e}");
    }
    let toml_err = toml::from_str::<CircuitSettings>("length_m = [60.0, 90.0]\nwidht_m = [2.0, 2.2]\n");
    assert!(toml_err.unwrap_err().to_string().contains("widht_m"));
    let part: CircuitSettings = toml::from_str("width_m = [2.0, 2.2]\n").unwrap();
    assert_eq!(
        part,
        CircuitSettings {
            width_m: [2.0, 2.2],
            ..s
        }
    );
}

/// `scene.circuit = { seed }` in a sim config builds the seed's circuit, its settings
/// defaulted, with the car at the first centre-line point heading to the second.
#[test]
fn a_circuit_scene_builds_from_its_seed_with_the_car_on_the_start_line() {
    let cfg: SimConfig = toml::from_str("[scene.circuit]\nseed = 11\n").unwrap();
    assert_eq!(
        cfg.scene,
        SceneSource::Circuit {
            seed: 11,
            settings: CircuitSettings::default()
        }
    );
    let (t, _) = MapTrack::generated(11, &CircuitSettings::default()).unwrap();
    let mut s = Sim::new(cfg).unwrap();
    assert_eq!(s.scene().centreline.as_ref(), Some(&t.centreline));
    run(&mut s, Control::default(), 10);
    let pose = s.car(0).pose2();
    let c = &t.centreline;
    let yaw = (c[1][1] - c[0][1]).atan2(c[1][0] - c[0][0]);
    assert!(
        (pose.x_m - c[0][0]).hypot(pose.y_m - c[0][1]) < 0.05,
        "{pose:?} vs {:?}",
        c[0]
    );
    assert!((pose.yaw_rad - yaw).abs() < 0.02, "{pose:?} vs yaw {yaw}");
}
