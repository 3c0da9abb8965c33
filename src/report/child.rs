//! One report run as a child process of this same binary (`prismap render … --stats
//! --error-csv`), so that its peak resident memory is its own. Its stats come back typed
//! ([`Stats`]), its per-pass error log as [`PassRecord`]s.

use std::path::PathBuf;
use std::process::Command;

use super::{Report, ReportError};
use crate::output::Stats;
use crate::photon::Storage;
use crate::render::PassRecord;
use crate::spectral::Upsampling;

pub struct Job<'a> {
    pub name: String,
    pub scene: &'a str,
    pub bins: usize,
    pub storage: Storage,
    pub photons: usize,
    pub limit: Limit,
    pub output: PathBuf,
    pub reference: Option<PathBuf>,
    /// How scene colours become spectra (the report's runs: Jakob–Hanika, but for the
    /// Smits pair that shows Algorithm 1 on the paper's own colours).
    pub spectra: Upsampling,
    /// Whether neighbouring pixels pool their final-gather rays (the runs: the default,
    /// yes; the reference: no, so it carries none of pooling's blur).
    pub pool: bool,
}

#[derive(Clone, Copy)]
pub enum Limit {
    Passes(u64),
    Seconds(f64),
}

impl Report {
    pub(super) fn runs_dir(&self) -> PathBuf {
        self.out.join("runs")
    }

    /// Runs one render as a child process; returns its stats and per-pass error log.
    pub(super) fn render(&self, job: &Job) -> Result<(Stats, Vec<PassRecord>), ReportError> {
        let stats_path = self.runs_dir().join(format!("{}.json", job.name));
        let csv = self
            .runs_dir()
            .join(format!("{}-convergence.csv", job.name));
        let mut cmd = Command::new(&self.exe);
        cmd.arg("render")
            .arg(job.scene)
            .args(["--bins", &job.bins.to_string()])
            .args(["--storage", job.storage.name()])
            .args(["--photons", &job.photons.to_string()])
            .args(["--size", &format!("{0}x{0}", self.plan.size)])
            .args(["--fg", &self.plan.final_gather_rays.to_string()])
            .args(["--seed", "1"])
            .args(["--spectra", job.spectra.name()])
            .arg("-o")
            .arg(&job.output)
            .arg("--stats")
            .arg(&stats_path);
        match job.limit {
            Limit::Passes(p) => cmd.args(["--passes", &p.to_string()]),
            Limit::Seconds(s) => cmd.args(["--seconds", &s.to_string()]),
        };
        if let Some(r) = &job.reference {
            cmd.arg("--reference").arg(r).arg("--error-csv").arg(&csv);
        }
        if !job.pool {
            cmd.arg("--no-fg-pool");
        }
        let out = cmd.output().map_err(|e| ReportError::io(&self.exe, e))?;
        if !out.status.success() {
            return Err(ReportError::Run {
                name: job.name.clone(),
                message: String::from_utf8_lossy(&out.stderr).trim().to_string(),
            });
        }
        let text =
            std::fs::read_to_string(&stats_path).map_err(|e| ReportError::io(&stats_path, e))?;
        let stats: Stats = serde_json::from_str(&text).map_err(|e| ReportError::Parse {
            path: stats_path.display().to_string(),
            message: e.to_string(),
        })?;
        let log = match &job.reference {
            Some(_) => read_error_csv(&csv)?,
            None => Vec::new(),
        };
        Ok((stats, log))
    }
}

/// Reads the `pass,seconds,photons,psnr_db` log that `prismap render --error-csv` writes.
fn read_error_csv(path: &std::path::Path) -> Result<Vec<PassRecord>, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReportError::io(path, e))?;
    let bad = |line: &str| ReportError::Parse {
        path: path.display().to_string(),
        message: format!("line '{line}' is not pass,seconds,photons,psnr_db"),
    };
    text.lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            let [pass, seconds, photons, psnr] = f[..] else {
                return Err(bad(line));
            };
            Ok(PassRecord {
                pass: pass.parse().map_err(|_| bad(line))?,
                seconds: seconds.parse().map_err(|_| bad(line))?,
                photons: photons.parse().map_err(|_| bad(line))?,
                psnr_db: Some(psnr.parse().map_err(|_| bad(line))?),
            })
        })
        .collect()
}
