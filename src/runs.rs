//! Run directories: named by UTC time, env and algorithm; built under a `.partial` name and
//! renamed when complete, so a run directory is never half-written.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// `YYYYMMDD-HHMMSS` in UTC.
pub fn stamp() -> String {
    jiff::Timestamp::now().strftime("%Y%m%d-%H%M%S").to_string()
}

/// Write `bytes` to `path` through a temporary file in the same directory, fsync and a rename
/// (agvrl-rl's, which policy files and checkpoints use too).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(agvrl_rl::write_atomic(path, bytes)?)
}

/// A run directory being filled.
pub struct RunDir {
    final_path: PathBuf,
    partial: PathBuf,
}

impl RunDir {
    /// Start `path` (created as `<path>.partial`). Refuses to overwrite an existing run, or one
    /// another process is writing.
    pub fn create(path: PathBuf) -> Result<Self> {
        Self::claim(&path)?.ok_or_else(|| anyhow::anyhow!("{} exists already; choose another --out", path.display()))
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
        anyhow::bail!("no free run directory name beside {}", base.display())
    }

    /// Claim `path` atomically: `<path>.partial` is created with `create_dir` (which fails if
    /// another process made it first), and the claim is given up if a finished run holds `path`.
    /// `None` when the name is taken.
    fn claim(path: &Path) -> Result<Option<Self>> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        let partial = PathBuf::from(format!("{}.partial", path.display()));
        match std::fs::create_dir(&partial) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Ok(None),
            Err(e) => return Err(e).with_context(|| format!("creating {}", partial.display())),
        }
        // A run that finished before our claim renamed its .partial away; its name stays taken.
        if path.exists() {
            let _ = std::fs::remove_dir(&partial);
            return Ok(None);
        }
        Ok(Some(Self {
            final_path: path.to_path_buf(),
            partial,
        }))
    }

    /// Path of a file inside the run.
    pub fn file(&self, name: &str) -> PathBuf {
        self.partial.join(name)
    }

    /// Publish the run under its final name.
    pub fn finish(self) -> Result<PathBuf> {
        std::fs::rename(&self.partial, &self.final_path)
            .with_context(|| format!("renaming {} to {}", self.partial.display(), self.final_path.display()))?;
        Ok(self.final_path)
    }
}

#[cfg(test)]
mod tests {
    use super::RunDir;

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
        let s = super::stamp();
        assert_eq!(s.len(), 15);
        let year: i32 = s[..4].parse().unwrap();
        assert!((2024..2200).contains(&year), "{s}");
        assert!((1..=12).contains(&s[4..6].parse::<u32>().unwrap()));
    }
}
