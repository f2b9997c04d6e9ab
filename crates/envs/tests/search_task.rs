//! The search task: subjects stand by trees and are found when the camera sees them; the
//! explored-ground observation.

use super::*;
use agvrl_envs::task::Search;
use agvrl_envs::task::search::SearchConfig;
use agvrl_envs::task::{ExploredObs, ObsConfig};
use agvrl_sim::PlanarPose;

#[test]
fn subjects_stand_by_trees_and_are_found_when_the_camera_sees_them() {
    let sim = agvrl_sim::SimConfig {
        scene: agvrl_sim::SceneSource::Builtin("outdoor-20".into()),
        settings: agvrl_sim::SimSettings {
            subjects: 3,
            subject_seed: 7,
            camera: Some(agvrl_sim::sensors::CameraConfig {
                width: 80,
                height: 60,
                ..Default::default()
            }),
            ..Default::default()
        },
    };
    let vehicle = SimVehicle::new(sim.clone(), SpawnMode::Fixed, Randomisation::default()).unwrap();
    let subjects = vehicle.map().unwrap().subjects.clone();
    assert_eq!(subjects.len(), 3);
    let scene = vehicle.sim().scene();
    let target = &scene.objects[subjects[0] as usize];
    let p = target.shapes[0].pose.translation;
    // Every subject stands near a tree (outdoor scenes have no buildings).
    for id in &subjects {
        let s = scene.objects[*id as usize].shapes[0].pose.translation;
        let near_tree = scene
            .file
            .objects
            .iter()
            .any(|o| o.model == "tree" && ((o.x_m - s.x).powi(2) + (o.y_m - s.y).powi(2)).sqrt() < 1.7);
        assert!(near_tree, "subject at ({}, {})", s.x, s.y);
    }
    let mut env = TaskEnv::new(vehicle, Search::new(SearchConfig::default(), 0.36));
    env.reset(Some(0)).unwrap();
    // Stand 3 m from the first subject, looking at it.
    let yaw = 0.3f32;
    let pose = PlanarPose {
        x_m: p.x - 3.0 * yaw.cos(),
        y_m: p.y - 3.0 * yaw.sin(),
        yaw_rad: yaw,
    };
    env.vehicle_mut().sim_mut().reset(pose).unwrap();
    let st = env.step(&[-1.0, 0.0]).unwrap();
    let info = st.info.search.unwrap();
    assert_eq!(info.subjects_total, 3);
    assert!(info.subjects_found >= 1, "{info:?}");
    assert_eq!(info.find_times_s.len(), info.subjects_found);
    // The same view with a 2 m detection range: 3 m away is too far.
    let v2 = SimVehicle::new(sim, SpawnMode::Fixed, Randomisation::default()).unwrap();
    let near_only = SearchConfig {
        found_range_m: 2.0,
        ..SearchConfig::default()
    };
    let mut env = TaskEnv::new(v2, Search::new(near_only, 0.36));
    env.reset(Some(0)).unwrap();
    env.vehicle_mut().sim_mut().reset(pose).unwrap();
    let st = env.step(&[-1.0, 0.0]).unwrap();
    assert_eq!(st.info.search.unwrap().subjects_found, 0);
}

fn cfg() -> EnvConfig {
    EnvConfig {
        observation: ObsConfig {
            explored: ExploredObs {
                sectors: 8,
                ..ExploredObs::default()
            },
            ..ObsConfig::default()
        },
        max_steps: 200,
        ..EnvConfig::default()
    }
}

#[test]
fn driving_ahead_leaves_new_ground_ahead_and_explored_ground_behind() {
    let mut env = make("search-outdoor-20", &cfg()).unwrap();
    assert_eq!(env.observation_space().dim(), 104 + 16);
    check_env(env.as_mut(), 60).unwrap();
    let (obs, _) = env.reset(Some(3)).unwrap();
    let ex = &obs[104..];
    assert!(ex.iter().all(|v| (0.0..=1.0).contains(v)), "{ex:?}");
    assert!(
        ex[8..].iter().all(|v| *v == 1.0),
        "nothing beyond 4 m explored yet: {ex:?}"
    );
    let mut last = obs;
    let mut moved = 0.0;
    for _ in 0..60 {
        let s = env.step(&[1.0, 0.0]).unwrap();
        assert!(!s.terminated, "the spawn has room to drive straight");
        moved = s.info.search.as_ref().unwrap().distance_m;
        last = s.obs;
    }
    assert!(moved > 1.0, "moved {moved} m");
    let ex = &last[104..];
    // Sector 0 is straight ahead, sector 4 behind (ring 2-4 m).
    assert!(ex[4] + 0.3 < ex[0], "behind {} ahead {}: {ex:?}", ex[4], ex[0]);
}

#[test]
fn racing_refuses_it_and_bad_rings_are_an_error() {
    let err = make("racing-oval", &cfg()).err().expect("a search observation");
    assert!(err.to_string().contains("observation.explored"), "{err}");
    let mut bad = cfg();
    bad.observation.explored.radii_m = [2.0, 2.0, 8.0];
    let err = make("search-urban-20", &bad).err().expect("empty ring");
    assert!(err.to_string().contains("radii_m"), "{err}");
}
