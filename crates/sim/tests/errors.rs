//! Bad vehicle, URDF, mesh and scene files give errors naming the file and the problem; non-finite
//! controls never reach physics.

use super::*;

fn write(dir: &std::path::Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

#[test]
fn broken_urdf_names_the_file_and_problem() {
    let d = tmpdir("badurdf");
    let toml = AssetSource::builtin().read("vehicles/xtenth_car.toml").unwrap();
    write(d.path(), "car.toml", &toml.replace("xtenth_car.urdf", "car.urdf"));
    write(d.path(), "car.urdf", "<robot name=\"x\"><link name=\"a\"></robot>");
    let e = Sim::new(SimConfig {
        settings: SimSettings {
            vehicle: d.path().join("car.toml").display().to_string(),
            ..Default::default()
        },
        ..SimConfig::default()
    })
    .err()
    .unwrap();
    let msg = e.to_string();
    assert!(msg.contains("car.urdf") && msg.contains("bad URDF"), "{msg}");
}

#[test]
fn vehicle_spec_naming_a_missing_joint_is_rejected() {
    let d = tmpdir("badjoint");
    let src = AssetSource::builtin();
    write(
        d.path(),
        "car.toml",
        &src.read("vehicles/xtenth_car.toml")
            .unwrap()
            .replace("rear_left_wheel_joint", "no_such_joint"),
    );
    write(
        d.path(),
        "xtenth_car.urdf",
        &src.read("vehicles/xtenth_car.urdf").unwrap(),
    );
    let e = Sim::new(SimConfig {
        settings: SimSettings {
            vehicle: d.path().join("car.toml").display().to_string(),
            ..Default::default()
        },
        ..SimConfig::default()
    })
    .err()
    .unwrap();
    assert!(e.to_string().contains("no_such_joint"), "{e}");
}

#[test]
fn missing_mesh_names_the_mesh_file() {
    let d = tmpdir("mesh");
    write(
        d.path(),
        "m.urdf",
        "<robot name=\"m\"><link name=\"a\"><collision><geometry><mesh filename=\"gone.obj\"/></geometry></collision></link></robot>",
    );
    let src = AssetSource::Dir(d.path().to_path_buf());
    let model = urdf::UrdfModel::read(&src, "m.urdf").unwrap();
    let e = model.collision_shapes(&src, Vector::ONE, |_| true).err().unwrap();
    assert!(e.to_string().contains("gone.obj"), "{e}");
}

#[test]
fn bad_scene_toml_names_the_file_and_key() {
    let d = tmpdir("scene");
    write(d.path(), "s.toml", "name = \"s\"\nkind = \"outdoor\"\nbogus_key = 1\n");
    let e = Sim::new(SimConfig {
        scene: SceneSource::File(d.path().join("s.toml")),
        ..SimConfig::default()
    })
    .err()
    .unwrap();
    let msg = e.to_string();
    assert!(msg.contains("s.toml") && msg.contains("bogus_key"), "{msg}");
    let e = Sim::new(SimConfig {
        scene: SceneSource::Builtin("moon".into()),
        ..SimConfig::default()
    })
    .err()
    .unwrap();
    assert!(e.to_string().contains("oval"), "lists the built-in scenes: {e}");
}

#[test]
fn scene_with_unknown_model_lists_known_models() {
    let d = tmpdir("model");
    write(
        d.path(),
        "s.toml",
        "name = \"s\"\nkind = \"outdoor\"\n[ground]\nsize_m = [10.0, 10.0]\nfriction = 1.0\ncolor = [0.5, 0.5, 0.5]\n[spawn]\nx_m = 0.0\ny_m = 0.0\nyaw_deg = 0.0\n[[object]]\nmodel = \"ufo\"\nx_m = 3.0\ny_m = 3.0\n",
    );
    let e = Sim::new(SimConfig {
        scene: SceneSource::File(d.path().join("s.toml")),
        ..SimConfig::default()
    })
    .err()
    .unwrap();
    let msg = e.to_string();
    assert!(msg.contains("ufo") && msg.contains("rock_1"), "{msg}");
}

#[test]
fn non_finite_controls_never_reach_physics() {
    let mut s = Sim::new(SimConfig::default()).unwrap();
    s.step(Control {
        throttle: f64::NAN,
        steering_rad: f64::INFINITY,
    })
    .unwrap();
    assert_eq!(
        s.car(0).control(),
        Control {
            throttle: 0.0,
            steering_rad: 0.0
        }
    );
    assert!(s.car(0).pose().is_finite());
}
