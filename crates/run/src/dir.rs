//! Run directories: their file names, building one (under a `.partial` name, renamed when
//! complete, so a run directory is never half-written), and reading one back.

use crate::config::RunConfig;
use crate::error::{Result, RunError};
use std::path::{Path, PathBuf};

/// The files of a run directory.
pub mod files {
    /// The fully resolved run configuration.
    pub const CONFIG: &str = "config.toml";
    /// The trained policy.
    pub const POLICY: &str = "policy.agvrl";
    /// The learner's checkpoint (`train --resume`).
    pub const CHECKPOINT: &str = "checkpoint.ckpt";
    /// Training metrics, one line per update.
    pub const METRICS: &str = "metrics.csv";
    /// The evaluation's `key=value` lines, with `train_s` and `eval_s`, for people.
    pub const EVAL: &str = "eval.txt";
    /// The same figures at full precision, for programs (`RunReport`).
    pub const EVAL_JSON: &str = "eval.json";
    /// Moving average of the episode return against steps.
    pub const LEARNING_CURVE: &str = "learning_curve.png";
    /// Top view of every evaluated path.
    pub const TRAJECTORY: &str = "trajectory.png";
    /// The first evaluation episode, for the rerun viewer.
    pub const RECORDING: &str = "eval.rrd";
    /// A self-play run's opponents: the learner's snapshots, `<steps>.agvrl` each (the step
    /// count it was taken at), which a resume draws from again.
    pub const POOL: &str = "pool";
}

/// `YYYYMMDD-HHMMSS` in UTC: the start of a run directory's default name.
pub fn stamp() -> String {
    jiff::Timestamp::now().strftime("%Y%m%d-%H%M%S").to_string()
}

/// A finished (or interrupted) run directory, read back.
#[derive(Clone, Debug)]
pub struct Run {
    dir: PathBuf,
    config: RunConfig,
}

impl Run {
    /// Open `dir`: its `config.toml` must be a valid run config.
    pub fn open(dir: &Path) -> Result<Self> {
        let config = RunConfig::load(&dir.join(files::CONFIG)).map_err(|e| {
            RunError::Config(format!(
                "{} is not a run directory: {}",
                dir.display(),
                crate::error_line(&e)
            ))
        })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            config,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Its run configuration.
    pub fn config(&self) -> &RunConfig {
        &self.config
    }

    /// Path of one of its files (see [`files`]).
    pub fn file(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Its evaluation (eval.json).
    pub fn report(&self) -> Result<crate::RunReport> {
        crate::RunReport::load(&self.file(files::EVAL_JSON))
    }

    /// Whether `policy` is the policy file of a run directory: then that run's config is its
    /// settings.
    pub fn of_policy(policy: &Path) -> Option<PathBuf> {
        let dir = policy.parent()?;
        (policy.file_name()? == files::POLICY && dir.join(files::CONFIG).is_file()).then(|| dir.to_path_buf())
    }
}

/// [`agvrl_sim::write_atomic`] (a temporary file in the same directory, fsync and a rename),
/// its error naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    agvrl_sim::write_atomic(path, bytes).map_err(io(path))
}

/// A run directory being filled.
pub struct RunDir {
    final_path: PathBuf,
    partial: PathBuf,
    /// Resuming a finished run: `finish` swaps the filled copy with it.
    replaces: bool,
    /// Remove `partial` when dropped unfinished (a resume that failed: its copy is no use).
    discard: bool,
    /// A lock on the resumed run's directory, so a second resume of it is refused; the
    /// kernel releases it when the process dies, however it dies.
    _lock: Option<std::fs::File>,
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl RunDir {
    /// Start `path` (created as `<path>.partial`). Refuses to overwrite an existing run, or one
    /// another process is writing.
    pub fn create(path: PathBuf) -> Result<Self> {
        Self::claim(&path)?
            .ok_or_else(|| RunError::RunDir(format!("{} exists already; choose another --out", path.display())))
    }

    /// Start `base`, or `base-2`, `base-3`, ... : the first name no other run holds, so any
    /// number of runs started in the same second get directories of their own.
    pub fn create_unique(base: PathBuf) -> Result<Self> {
        for k in 1..10_000 {
            let path = if k == 1 {
                base.clone()
            } else {
                PathBuf::from(format!("{}-{k}", base.display()))
            };
            if let Some(run) = Self::claim(&path)? {
                return Ok(run);
            }
        }
        Err(RunError::RunDir(format!(
            "no free run directory name beside {}",
            base.display()
        )))
    }

    /// Claim `path` atomically: `<path>.partial` is created with `create_dir` (which fails if
    /// another process made it first), and the claim is given up if a finished run holds `path`.
    /// `None` when the name is taken.
    fn claim(path: &Path) -> Result<Option<Self>> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        let partial = PathBuf::from(format!("{}.partial", path.display()));
        match std::fs::create_dir(&partial) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Ok(None),
            Err(e) => return Err(io(&partial)(e)),
        }
        // A run that finished before our claim renamed its .partial away; its name stays taken.
        if path.exists() {
            let _ = std::fs::remove_dir(&partial);
            return Ok(None);
        }
        Ok(Some(Self {
            final_path: path.to_path_buf(),
            partial,
            replaces: false,
            discard: false,
            _lock: None,
        }))
    }

    /// Continue the run at `dir` without changing it before the continued run is complete.
    ///
    /// - A finished run is copied to `<dir>.resume.partial` (its checkpoint hard-linked: a
    ///   checkpoint is only ever replaced, never written in place), the copy is filled, and
    ///   [`RunDir::finish`] swaps the two in one rename. A killed resume leaves `dir` as it was
    ///   and a `.resume.partial` that the next resume removes.
    /// - A `<name>.partial` run (a training killed before it finished) is continued where it
    ///   lies and published as `<name>` by `finish`.
    pub fn resume(dir: &Path) -> Result<Self> {
        let shown = dir.display().to_string();
        if let Some(name) = shown.strip_suffix(".resume.partial") {
            return Err(RunError::RunDir(format!(
                "{shown} is the leftover of a resume that did not finish; resume {name} instead"
            )));
        }
        if let Some(name) = shown.strip_suffix(".partial") {
            return Ok(Self {
                final_path: PathBuf::from(name),
                partial: dir.to_path_buf(),
                replaces: false,
                discard: false,
                _lock: Some(lock(dir)?),
            });
        }
        if !dir.is_dir() {
            return Err(RunError::RunDir(format!("{shown} is not a run directory")));
        }
        let lock = lock(dir)?;
        let partial = PathBuf::from(format!("{shown}.resume.partial"));
        if partial.exists() {
            eprintln!("removing {} (a resume that did not finish)", partial.display());
            std::fs::remove_dir_all(&partial).map_err(io(&partial))?;
        }
        copy_run(dir, &partial)?;
        Ok(Self {
            final_path: dir.to_path_buf(),
            partial,
            replaces: true,
            discard: true,
            _lock: Some(lock),
        })
    }

    /// Path of a file inside the run (see [`files`]).
    pub fn file(&self, name: &str) -> PathBuf {
        self.partial.join(name)
    }

    /// Publish the run under its final name (a resumed finished run: in place of the old one).
    pub fn finish(mut self) -> Result<PathBuf> {
        if self.replaces {
            exchange(&self.partial, &self.final_path)?;
            // The old run now lies under the partial name; a kill here leaves it to the next
            // resume to remove.
            std::fs::remove_dir_all(&self.partial).map_err(io(&self.partial))?;
            self.discard = false;
            return Ok(self.final_path.clone());
        }
        if self.final_path.exists() {
            return Err(RunError::RunDir(format!(
                "the run is complete in {}, but {} exists: rename it yourself",
                self.partial.display(),
                self.final_path.display()
            )));
        }
        std::fs::rename(&self.partial, &self.final_path).map_err(|source| {
            RunError::RunDir(format!(
                "renaming {} to {}: {source}",
                self.partial.display(),
                self.final_path.display()
            ))
        })?;
        Ok(self.final_path.clone())
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if self.discard {
            let _ = std::fs::remove_dir_all(&self.partial);
        }
    }
}

/// An exclusive lock on the directory `dir`, or a clear error when another process holds it.
fn lock(dir: &Path) -> Result<std::fs::File> {
    use std::os::fd::AsRawFd;
    let file = std::fs::File::open(dir).map_err(io(dir))?;
    // SAFETY: flock on a descriptor this function owns.
    if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        return Err(RunError::RunDir(format!(
            "another process is resuming {}",
            dir.display()
        )));
    }
    Ok(file)
}

/// Copy the run directory `from` to `to` (created) for a resume: the files only ever replaced
/// whole ([`write_atomic`]) are hard-linked where the file system allows, the evaluation's
/// recording and plots (written in place, and written anew by the resume) are left out, and
/// anything else is copied, subdirectories recursed.
fn copy_run(from: &Path, to: &Path) -> Result<()> {
    const LINKED: [&str; 6] = [
        files::CONFIG,
        files::POLICY,
        files::CHECKPOINT,
        files::METRICS,
        files::EVAL,
        files::EVAL_JSON,
    ];
    const REDONE: [&str; 3] = [files::RECORDING, files::LEARNING_CURVE, files::TRAJECTORY];
    std::fs::create_dir(to).map_err(io(to))?;
    for entry in std::fs::read_dir(from).map_err(io(from))? {
        let entry = entry.map_err(io(from))?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().map_err(io(&src))?.is_dir() {
            copy_run(&src, &dst)?;
        } else if REDONE.contains(&name.as_str()) {
            continue;
        } else if !LINKED.contains(&name.as_str()) || std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(io(&dst))?;
        }
    }
    // The copy is complete on disk before anything relies on it.
    std::fs::File::open(to).and_then(|d| d.sync_all()).map_err(io(to))
}

/// Swap the directories `a` and `b` in one step (`renameat2` with `RENAME_EXCHANGE`); where
/// the file system cannot, `b` moves aside first (a kill between the two renames leaves both).
fn exchange(a: &Path, b: &Path) -> Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        CString::new(p.as_os_str().as_bytes()).map_err(|_| RunError::RunDir(format!("{} has a NUL", p.display())))
    };
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: two NUL-terminated paths that outlive the call.
    let rc = unsafe {
        libc::syscall(
            libc::SYS_renameat2,
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        return Ok(());
    }
    let aside = PathBuf::from(format!("{}.old.partial", b.display()));
    std::fs::rename(b, &aside).map_err(io(b))?;
    std::fs::rename(a, b).map_err(io(a))?;
    std::fs::rename(&aside, a).map_err(io(&aside))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resumed_run_is_untouched_until_it_is_swapped_in_whole() {
        let root = std::env::temp_dir().join(format!("agvrl-resume-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let done = root.join("run");
        let new = RunDir::create(done.clone()).unwrap();
        for (name, text) in [
            (files::CONFIG, "old config"),
            (files::CHECKPOINT, "old ckpt"),
            ("sub/x", "x"),
        ] {
            std::fs::create_dir_all(new.file(name).parent().unwrap()).unwrap();
            std::fs::write(new.file(name), text).unwrap();
        }
        new.finish().unwrap();
        // A resume killed earlier left its copy; the next one removes it.
        std::fs::create_dir(root.join("run.resume.partial")).unwrap();
        let resumed = RunDir::resume(&done).unwrap();
        assert!(
            RunDir::resume(&done).is_err(),
            "a second resume of the same run is refused"
        );
        write_atomic(&resumed.file(files::CHECKPOINT), b"new ckpt").unwrap();
        assert_eq!(std::fs::read_to_string(resumed.file("sub/x")).unwrap(), "x");
        assert_eq!(
            std::fs::read_to_string(done.join(files::CHECKPOINT)).unwrap(),
            "old ckpt"
        );
        assert_eq!(resumed.finish().unwrap(), done);
        assert_eq!(
            std::fs::read_to_string(done.join(files::CHECKPOINT)).unwrap(),
            "new ckpt"
        );
        assert_eq!(std::fs::read_to_string(done.join(files::CONFIG)).unwrap(), "old config");
        assert!(!root.join("run.resume.partial").exists());
        // A killed new training is continued where it lies and published under its name.
        let partial = RunDir::create(root.join("killed")).unwrap();
        std::fs::write(partial.file(files::CONFIG), "c").unwrap();
        std::mem::forget(partial);
        let resumed = RunDir::resume(&root.join("killed.partial")).unwrap();
        assert_eq!(resumed.finish().unwrap(), root.join("killed"));
        assert!(root.join("killed").join(files::CONFIG).is_file());
        assert!(RunDir::resume(&root.join("run.resume.partial")).is_err());
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn a_run_directory_name_is_claimed_once() {
        let dir = std::env::temp_dir().join(format!("agvrl-claim-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let base = dir.join("runs").join("x");
        let a = RunDir::create_unique(base.clone()).unwrap();
        let b = RunDir::create_unique(base.clone()).unwrap();
        assert!(RunDir::create(base.clone()).is_err(), "x is being written");
        let a = a.finish().unwrap();
        let c = RunDir::create_unique(base.clone()).unwrap();
        assert_eq!(a, base);
        assert_eq!(b.finish().unwrap(), dir.join("runs").join("x-2"));
        // x is finished and x-2 too: the next claim skips both.
        assert_eq!(c.finish().unwrap(), dir.join("runs").join("x-3"));
        assert!(RunDir::create(base).is_err(), "a finished run is never overwritten");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stamp_is_a_plausible_utc_time() {
        let s = stamp();
        assert_eq!(s.len(), 15);
        let year: i32 = s[..4].parse().unwrap();
        assert!((2024..2200).contains(&year), "{s}");
        assert!((1..=12).contains(&s[4..6].parse::<u32>().unwrap()));
    }

    #[test]
    fn a_directory_without_a_run_config_is_not_a_run() {
        let dir = std::env::temp_dir().join(format!("agvrl-notrun-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = Run::open(&dir).unwrap_err().to_string();
        assert!(e.contains("is not a run directory"), "{e}");
        assert!(e.contains(files::CONFIG), "{e}");
        assert!(Run::of_policy(&dir.join(files::POLICY)).is_none());
        std::fs::write(dir.join(files::CONFIG), "env = \"racing-oval\"\n").unwrap();
        let run = Run::open(&dir).unwrap();
        assert_eq!(run.config().env, "racing-oval");
        assert_eq!(Run::of_policy(&dir.join(files::POLICY)), Some(dir.clone()));
        assert!(Run::of_policy(&dir.join("other.agvrl")).is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
