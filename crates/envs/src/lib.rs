//! agvrl-envs: the reinforcement-learning contract. `Env` (Gymnasium semantics), the `Vehicle`
//! seam shared by the simulator and a real car, the paper's tasks, the registry, `VecEnv`, and
//! the sim-to-real wrappers.
//!
//! ```text
//! action in [-1,1]^2 -> Task::control -> Control -> Vehicle::actuate (one control period)
//!   -> Vehicle::sense -> SensorFrame -> Task: observation, reward, termination
//!   -> TimeLimit (truncation) -> VecEnv (auto-reset, final_obs) -> learner
//! ```
//!
//! Invariants: `api` sees agvrl-sim only through its plain `msg` types (the oval's geometry,
//! `api::OvalTrack`, is the task's own); rewards live only in
//! `task::reward`; every random draw comes from a RNG seeded through `reset`; a NaN or
//! wrong-length action is an error and never reaches the vehicle.
#![warn(missing_docs)]

pub mod api;
pub mod check;
pub mod drivers;
pub mod heldout;
pub mod pass_advice;
pub mod passer;
pub mod pendulum;
pub mod race_env;
pub mod race_figures;
pub mod registry;
pub mod sim_vehicle;
pub mod task;
pub mod task_env;
pub mod vec_env;
pub mod workers;
pub mod wrappers;

/// Order statistics (agvrl-sim's), for the crates above.
pub use api::{BoxSpace, Control, Env, EnvError, Info, MultiEnv, MultiStep, RaceSummary, SensorFrame, Step, Vehicle};
pub use check::{CheckError, check_env};
pub use drivers::{
    CarLimits, Driver, FollowTheGap, FollowTheGapSettings, PurePursuit, PurePursuitSettings, RacePath, parse_raceline,
};
pub use race_env::{CarInput, RaceEnv, RaceSettings};
pub use registry::{
    ENV_IDS, ENVS, EnvConfig, EnvSpec, MULTI_ENV_IDS, TaskKind, TrackSetting, lone_car_id, make, make_multi, make_race,
    make_sim_car, make_task, make_vehicle,
};
pub use sim_vehicle::{Randomisation, SimCar, SimVehicle, SpawnMode};
pub use task::ActionMapping;
pub use task_env::TaskEnv;
pub use vec_env::{Autoreset, VecEnv, VecStep};
pub use workers::Workers;
