//! `agvrl eval --record DIR`: every evaluated episode as a rosbag2 bag (`DIR/episode-000`, ...)
//! with the topics of `agvrl-drive --record` in simulated time, so a simulator log and a car
//! log open, and replay (`agvrl-drive --replay`), in the same tools.

use crate::episode::StepView;
use agvrl_deploy::hardware::config::{DriveMapping, Topics};
use agvrl_deploy::hardware::frames::Subscribed;
use agvrl_deploy::record::{self, BagCar, DriveBag};
use agvrl_deploy::{DeployError, Tick};
use agvrl_envs::EnvConfig;
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// One bag per episode, written as the episodes run.
pub struct EpisodeBags {
    dir: PathBuf,
    policy: Option<PathBuf>,
    env_id: String,
    env_cfg: EnvConfig,
    topics: Topics,
    drive: DriveMapping,
    open: Option<Open>,
    /// The bags written: directory and message count.
    pub written: Vec<(PathBuf, u64)>,
}

struct Open {
    bag: DriveBag,
    dir: PathBuf,
    /// Stamp of the frame the next control acts on.
    stamp_s: f64,
}

/// The bag directory of episode `k`.
pub fn episode_dir(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("episode-{k:03}"))
}

impl EpisodeBags {
    /// Bags under `dir` (which must not exist, or be empty) for the episodes of `env_id` driven
    /// by the policy file `policy` (`None`: random actions or a planner).
    pub fn new(dir: &Path, policy: Option<&Path>, env_id: &str, env_cfg: &EnvConfig) -> Result<Self> {
        if dir.exists() && std::fs::read_dir(dir)?.next().is_some() {
            bail!(
                "{} exists and is not empty: --record needs a directory of its own",
                dir.display()
            );
        }
        // The recorded drive commands carry the simulated car's own limits.
        let model = env_cfg.sim.vehicle_model()?;
        let mut drive = DriveMapping {
            steering_limit_rad: model.spec.steering.max_rad,
            ..DriveMapping::default()
        };
        drive.for_trained_top_speed(model.top_speed_mps());
        Ok(Self {
            dir: dir.to_path_buf(),
            policy: policy.map(Path::to_path_buf),
            env_id: env_id.to_string(),
            env_cfg: env_cfg.clone(),
            topics: Topics::default(),
            drive,
            open: None,
            written: Vec::new(),
        })
    }

    /// Record step `v`: a reset opens the episode's bag; a step records the command and the
    /// tick of the frame before it, then its own frame; the episode's last step closes the bag.
    pub fn see(&mut self, v: &StepView<'_>) -> Result<()> {
        let period_s = v.sim.config().settings.control_period_s as f32;
        if v.step == 0 {
            self.close()?;
            let dir = episode_dir(&self.dir, v.episode);
            let car = BagCar {
                topics: &self.topics,
                sensors: Subscribed::of_frame(v.frame),
                drive: self.drive,
                sim_time: true,
            };
            let bag = record::for_policy(&dir, self.policy.as_deref(), &self.env_id, &self.env_cfg, car)
                .with_context(|| format!("recording episode {}", v.episode))?;
            bag.frame(v.frame, period_s);
            self.open = Some(Open {
                bag,
                dir,
                stamp_s: v.frame.stamp_s,
            });
            return Ok(());
        }
        let Some(o) = &mut self.open else {
            return Ok(());
        };
        let control = v.frame.applied;
        o.bag.command(control, o.stamp_s);
        let (inference, infer_us) = match v.acted {
            Some(a) => (Some((a.observation.clone(), a.action.clone())), a.act_us),
            None => (None, 0.0),
        };
        o.bag.tick(&Tick {
            index: v.step - 1,
            stamp_s: o.stamp_s,
            control,
            event: None,
            intervention: v.intervention,
            infer_us,
            late_s: 0.0,
            tick_us: 0.0,
            now_s: o.stamp_s,
            sensed_wall_s: o.stamp_s,
            racing: None,
            termination: None,
            inference,
            passed: None,
        });
        o.bag.frame(v.frame, period_s);
        o.stamp_s = v.frame.stamp_s;
        if v.done {
            self.close()?;
        }
        Ok(())
    }

    fn close(&mut self) -> Result<()> {
        if let Some(o) = self.open.take() {
            let s = o.bag.finish().map_err(|e: DeployError| anyhow::anyhow!(e))?;
            self.written.push((o.dir, s.messages()));
        }
        Ok(())
    }

    /// Close the last bag; the bags written.
    pub fn finish(mut self) -> Result<Vec<(PathBuf, u64)>> {
        self.close()?;
        Ok(self.written)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recorded drive commands are clipped to the simulated car's steering limit, not
    /// XTENTH-CAR's: the F1TENTH car steers to 0.4189 rad.
    #[test]
    fn bags_carry_the_simulated_cars_steering_limit() {
        let dir = tempfile::tempdir().unwrap();
        for (vehicle, limit) in [("xtenth_car", 0.36), ("f1tenth", 0.4189)] {
            let mut cfg = EnvConfig::default();
            cfg.sim.vehicle = vehicle.into();
            let bags = EpisodeBags::new(&dir.path().join(vehicle), None, "racing-oval", &cfg).unwrap();
            assert_eq!(bags.drive.steering_limit_rad, limit, "{vehicle}");
        }
    }
}
