//! Run directories: named by UTC time, env and algorithm; built under a `.partial` name and
//! renamed when complete, so a run directory is never half-written.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// `YYYYMMDD-HHMMSS` in UTC.
pub fn stamp() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Write `bytes` to `path` through a temporary file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming to {}", path.display()))?;
    Ok(())
}

/// A run directory being filled.
pub struct RunDir {
    final_path: PathBuf,
    partial: PathBuf,
}

impl RunDir {
    /// Start `path` (created as `<path>.partial`). Refuses to overwrite an existing run.
    pub fn create(path: PathBuf) -> Result<Self> {
        if path.exists() {
            anyhow::bail!("{} exists already; choose another --out", path.display());
        }
        let partial = PathBuf::from(format!("{}.partial", path.display()));
        std::fs::create_dir_all(&partial).with_context(|| format!("creating {}", partial.display()))?;
        Ok(Self {
            final_path: path,
            partial,
        })
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
    #[test]
    fn stamp_is_a_plausible_utc_time() {
        let s = super::stamp();
        assert_eq!(s.len(), 15);
        let year: i32 = s[..4].parse().unwrap();
        assert!((2024..2200).contains(&year), "{s}");
        assert!((1..=12).contains(&s[4..6].parse::<u32>().unwrap()));
    }
}
