//! A simulator run's ground truth (`truth.csv`: `t_s`, then the plant's pose, motion, wheel
//! angles and speeds, steering mode), read whole and looked up by time for a dataset's grid.
//! Its numeric columns are named `truth_*` (the steering mode, text, is left out), each with
//! the unit its name carries.

use std::io::BufRead;
use std::path::{Path, PathBuf};

/// Why a truth file was refused: the file, and the line where that is the problem.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TruthError {
    /// It could not be read.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Empty, or its first column is not `t_s`.
    #[error("{}: {reason}", file.display())]
    NotTruth {
        /// The file.
        file: PathBuf,
        /// Why not.
        reason: &'static str,
    },
    /// A line's cell is not a number, or its time is before the line above's.
    #[error("{}: line {line}: {reason}", file.display())]
    Line {
        /// The file.
        file: PathBuf,
        /// The line (1 is the header).
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// A run's truth table, and where the last lookup was.
#[derive(Debug, Clone)]
pub struct Truth {
    columns: Vec<String>,
    rows: Vec<(f64, Vec<f64>)>,
    next: usize,
}

/// The file's lines after its header.
type Lines = std::io::Lines<std::io::BufReader<std::fs::File>>;

impl Truth {
    /// The `truth_*` column names of the file at `path` (its header only).
    pub fn columns_of(path: &Path) -> Result<Vec<String>, TruthError> {
        Ok(Truth::header(path)?.1)
    }

    /// The file's lines after the header, the `truth_*` names, and which CSV columns they are.
    fn header(path: &Path) -> Result<(Lines, Vec<String>, Vec<usize>), TruthError> {
        let io = |source| TruthError::Io {
            file: path.to_path_buf(),
            source,
        };
        let not_truth = |reason| TruthError::NotTruth {
            file: path.to_path_buf(),
            reason,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let mut lines = std::io::BufReader::new(file).lines();
        let header = lines
            .next()
            .transpose()
            .map_err(io)?
            .ok_or_else(|| not_truth("empty"))?;
        let names: Vec<&str> = header.split(',').collect();
        if names.first() != Some(&"t_s") {
            return Err(not_truth("not a truth.csv (its first column is not t_s)"));
        }
        let numeric: Vec<usize> = names
            .iter()
            .enumerate()
            .skip(1)
            .filter(|(_, name)| **name != "steering_mode")
            .map(|(i, _)| i)
            .collect();
        let columns = numeric
            .iter()
            .filter_map(|&i| names.get(i))
            .map(|name| format!("truth_{name}"))
            .collect();
        Ok((lines, columns, numeric))
    }

    /// The whole file at `path` (a run's truth is small: 100 rows a simulated second).
    pub fn read(path: &Path) -> Result<Truth, TruthError> {
        let (lines, columns, numeric) = Truth::header(path)?;
        let mut rows: Vec<(f64, Vec<f64>)> = Vec::new();
        for (n, line) in lines.enumerate() {
            let line_error = |reason: String| TruthError::Line {
                file: path.to_path_buf(),
                line: n + 2,
                reason,
            };
            let line = line.map_err(|source| TruthError::Io {
                file: path.to_path_buf(),
                source,
            })?;
            let cells: Vec<&str> = line.split(',').collect();
            let number = |i: usize| {
                cells
                    .get(i)
                    .and_then(|c| c.parse::<f64>().ok())
                    .ok_or_else(|| line_error(format!("column {} is not a number", i + 1)))
            };
            let t = number(0)?;
            let values = numeric
                .iter()
                .map(|&i| number(i))
                .collect::<Result<_, _>>()?;
            if rows.last().is_some_and(|(last, _)| t < *last) {
                return Err(line_error("time goes backwards".into()));
            }
            rows.push((t, values));
        }
        Ok(Truth {
            columns,
            rows,
            next: 0,
        })
    }

    /// The `truth_*` column names.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The last row at or before `t` (s), or NaNs before the first; times asked in order (a
    /// grid's) are found without a search.
    pub fn at(&mut self, t: f64) -> Vec<f64> {
        if self
            .next
            .checked_sub(1)
            .and_then(|i| self.rows.get(i))
            .is_some_and(|(rt, _)| *rt > t + 1e-9)
        {
            // Asked for an earlier time: from the start again.
            self.next = 0;
        }
        while self
            .rows
            .get(self.next)
            .is_some_and(|(rt, _)| *rt <= t + 1e-9)
        {
            self.next += 1;
        }
        match self.next.checked_sub(1).and_then(|i| self.rows.get(i)) {
            Some((_, values)) => values.clone(),
            None => vec![f64::NAN; self.columns.len()],
        }
    }

    /// The unit a truth column's name carries (`truth_vx_m_s`: m/s), or none.
    pub fn unit(name: &str) -> &'static str {
        [
            ("_m_s", "m/s"),
            ("_rad_s", "rad/s"),
            ("_deg", "deg"),
            ("_rad", "rad"),
            ("_m", "m"),
        ]
        .iter()
        .find(|(suffix, _)| name.ends_with(suffix))
        .map_or("", |(_, unit)| unit)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn file(name: &str, text: &str) -> PathBuf {
        let path = std::env::temp_dir().join(format!("bywire-truth-{}-{name}", std::process::id()));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn rows_are_found_by_time_and_mistakes_name_the_line() {
        let path = file(
            "ok.csv",
            "t_s,x_m,steering_mode,vx_m_s\n0.00,1.0,normal,0.5\n0.01,1.5,normal,0.6\n",
        );
        let mut truth = Truth::read(&path).unwrap();
        assert_eq!(truth.columns(), ["truth_x_m", "truth_vx_m_s"]);
        assert!(truth.at(-1.0).iter().all(|v| v.is_nan()));
        assert_eq!(truth.at(0.005), [1.0, 0.5]);
        assert_eq!(truth.at(0.02), [1.5, 0.6]);
        // Back in time: found again.
        assert_eq!(truth.at(0.0), [1.0, 0.5]);
        assert_eq!(Truth::unit("truth_vx_m_s"), "m/s");
        assert_eq!(Truth::unit("truth_yaw_rad"), "rad");
        std::fs::remove_file(&path).ok();
        for (name, text, says) in [
            ("empty.csv", "", "empty"),
            ("other.csv", "time,x\n", "first column is not t_s"),
            (
                "nan.csv",
                "t_s,x_m\n0.0,abc\n",
                "line 2: column 2 is not a number",
            ),
            (
                "back.csv",
                "t_s,x_m\n1.0,1\n0.5,1\n",
                "line 3: time goes backwards",
            ),
        ] {
            let path = file(name, text);
            let error = Truth::read(&path).unwrap_err().to_string();
            assert!(error.contains(says), "{error}");
            assert!(error.starts_with(&path.display().to_string()), "{error}");
            std::fs::remove_file(&path).ok();
        }
    }
}
