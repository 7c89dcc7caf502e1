//! rosbag2 folders as `ros2 bag` records and plays them with its MCAP storage: a
//! `metadata.yaml` beside the MCAP file it names. bywire writes one MCAP file of
//! `can_msgs/msg/Frame` on `/from_can_bus` ([`crate::mcap::McapWriter`]) and the metadata
//! describing it; it reads a bag of one MCAP file back as that file. The metadata is read for
//! the keys that matter here (the storage and the files), line by line as rosbag2 writes it.

use std::path::{Path, PathBuf};

use crate::mcap::{SCHEMA_NAME, TOPIC};

/// The metadata file's name.
pub const METADATA: &str = "metadata.yaml";

/// The bag's MCAP file, as its folder names it.
pub fn mcap_file_name(folder: &Path) -> String {
    let stem = folder
        .file_name()
        .map_or("bag".into(), |n| n.to_string_lossy().into_owned());
    format!("{stem}_0.mcap")
}

/// Why a folder is no bag bywire reads.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// No metadata, or it cannot be read.
    #[error("{path}: {reason}")]
    Metadata {
        /// The metadata file.
        path: String,
        /// Why.
        reason: String,
    },
}

/// The MCAP file of the bag in `folder` (its metadata must say MCAP storage and one file).
pub fn mcap_file(folder: &Path) -> Result<PathBuf, BagError> {
    let path = folder.join(METADATA);
    let fail = |reason: String| BagError::Metadata {
        path: path.display().to_string(),
        reason,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| fail(e.to_string()))?;
    let mut storage = None;
    let mut files = Vec::new();
    let mut in_files = false;
    for line in text.lines() {
        let trimmed = line.trim();
        if let Some(list_item) = trimmed.strip_prefix("- ").filter(|_| in_files) {
            files.push(list_item.trim().trim_matches('"').to_string());
            continue;
        }
        in_files = false;
        if let Some(value) = trimmed.strip_prefix("storage_identifier:") {
            storage = Some(value.trim().trim_matches('"').to_string());
        } else if trimmed == "relative_file_paths:" {
            in_files = true;
        }
    }
    match storage.as_deref() {
        Some("mcap") => {}
        Some(other) => {
            return Err(fail(format!(
                "storage '{other}': only MCAP bags are read (convert with `ros2 bag convert`)"
            )))
        }
        None => return Err(fail("no storage_identifier: not rosbag2 metadata".into())),
    }
    match files.as_slice() {
        [one] => {
            // The name only: a bag's files are beside its metadata, as rosbag2 finds them.
            let name = Path::new(one)
                .file_name()
                .ok_or_else(|| fail(format!("file '{one}'")))?;
            Ok(folder.join(name))
        }
        [] => Err(fail("relative_file_paths names no file".into())),
        many => Err(fail(format!(
            "a bag split into {} files: read each file on its own",
            many.len()
        ))),
    }
}

/// What the bag holds, for its metadata.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Summary {
    /// Messages written.
    pub messages: u64,
    /// The first and last message's time, ns since the Unix epoch.
    pub first_ns: u64,
    /// The last.
    pub last_ns: u64,
}

/// The metadata of a bag of `file` holding `summary` (rosbag2's version 5 layout: what
/// Humble and later read).
pub fn metadata(file: &str, summary: &Summary) -> String {
    let duration = summary.last_ns.saturating_sub(summary.first_ns);
    let start = if summary.messages == 0 {
        0
    } else {
        summary.first_ns
    };
    let count = summary.messages;
    format!(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  duration:\n    nanoseconds: {duration}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n  message_count: {count}\n  topics_with_message_count:\n    - topic_metadata:\n        name: {TOPIC}\n        type: {SCHEMA_NAME}\n        serialization_format: cdr\n        offered_qos_profiles: \"\"\n      message_count: {count}\n  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - {file}\n  files:\n    - path: {file}\n      starting_time:\n        nanoseconds_since_epoch: {start}\n      duration:\n        nanoseconds: {duration}\n      message_count: {count}\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_names_its_file_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("drive");
        std::fs::create_dir(&bag).unwrap();
        let name = mcap_file_name(&bag);
        assert_eq!(name, "drive_0.mcap");
        let summary = Summary {
            messages: 3,
            first_ns: 10,
            last_ns: 30,
        };
        std::fs::write(bag.join(METADATA), metadata(&name, &summary)).unwrap();
        assert_eq!(mcap_file(&bag).unwrap(), bag.join("drive_0.mcap"));
        let sqlite = metadata(&name, &summary)
            .replace("storage_identifier: mcap", "storage_identifier: sqlite3");
        std::fs::write(bag.join(METADATA), sqlite).unwrap();
        let err = mcap_file(&bag).unwrap_err().to_string();
        assert!(
            err.contains("metadata.yaml") && err.contains("sqlite3"),
            "{err}"
        );
        let split = metadata(&name, &summary).replace(
            "relative_file_paths:\n    - drive_0.mcap\n",
            "relative_file_paths:\n    - drive_0.mcap\n    - drive_1.mcap\n",
        );
        std::fs::write(bag.join(METADATA), split).unwrap();
        let err = mcap_file(&bag).unwrap_err().to_string();
        assert!(err.contains("split into 2 files"), "{err}");
    }
}
