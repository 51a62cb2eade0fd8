//! The key expressions of a team.

use crate::error::{NetError, Result};

/// Longest team or node name, bytes.
const MAX_NAME: usize = 64;

/// Checks a team, node or robot name: 1-64 ASCII letters, digits, `_` or `-` (so that it
/// is one key-expression chunk and a file name).
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > MAX_NAME {
        return Err(format!("'{name}' must be 1 to {MAX_NAME} characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-'))
    {
        return Err(format!(
            "'{name}' holds '{c}': use ASCII letters, digits, '_' and '-'"
        ));
    }
    Ok(())
}

/// The key expressions of one team, all under `olmap/TEAM/`:
///
/// | key | payload | who publishes | congestion |
/// |---|---|---|---|
/// | `olmap/TEAM/rec/ROBOT/SEQ` | record | the robot that recorded it; every node answers `get` on `rec/ROBOT/*` | Block |
/// | `olmap/TEAM/digest/NODE` | digest | every node, periodically | Drop |
/// | `olmap/TEAM/status/NODE` | status (JSON) | every node, periodically | Drop |
/// | `olmap/TEAM/alive/NODE` | liveliness token | every node while it runs | — |
/// | `olmap/TEAM/map` | `.olm` bytes (queryable) | the mapper | — |
/// | `olmap/TEAM/poses` | pose list text (queryable) | the mapper | — |
/// | `olmap/TEAM/write` | queryable: the mapper writes its outputs, replies with the folder | the mapper | — |
///
/// `ROBOT` and `SEQ` are decimal numbers (the record's key), `NODE` a node name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    /// The keys of team `team` (checked with [`check_name`]).
    pub fn new(team: &str) -> Result<Keys> {
        check_name(team).map_err(|e| NetError::InvalidArgument(format!("team name {e}")))?;
        Ok(Keys {
            prefix: format!("olmap/{team}"),
        })
    }

    /// `olmap/TEAM`.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The key of record `(robot, seq)`.
    pub fn record(&self, robot: u32, seq: u32) -> String {
        format!("{}/rec/{robot}/{seq}", self.prefix)
    }

    /// Every record of every robot.
    pub fn records(&self) -> String {
        format!("{}/rec/**", self.prefix)
    }

    /// Every record of one robot (the selector of a fetch).
    pub fn records_of(&self, robot: u32) -> String {
        format!("{}/rec/{robot}/*", self.prefix)
    }

    /// The `(robot, seq)` a record key names, if it is one (seq `u32::MAX` is reserved:
    /// never a record).
    pub fn parse_record(&self, key: &str) -> Option<(u32, u32)> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix("/rec/")?;
        let (robot, seq) = rest.split_once('/')?;
        let canonical = |s: &str| {
            !s.is_empty()
                && s.bytes().all(|b| b.is_ascii_digit())
                && (s == "0" || !s.starts_with('0'))
        };
        if !canonical(robot) || !canonical(seq) {
            return None;
        }
        // The last seq is reserved: digests describe holdings as half-open ranges.
        let seq: u32 = seq.parse().ok()?;
        (seq < u32::MAX).then_some((robot.parse().ok()?, seq))
    }

    /// A node's digest key; [`Keys::digests`] for all.
    pub fn digest(&self, node: &str) -> String {
        format!("{}/digest/{node}", self.prefix)
    }

    /// Every node's digest.
    pub fn digests(&self) -> String {
        format!("{}/digest/*", self.prefix)
    }

    /// A node's status key.
    pub fn status(&self, node: &str) -> String {
        format!("{}/status/{node}", self.prefix)
    }

    /// Every node's status.
    pub fn statuses(&self) -> String {
        format!("{}/status/*", self.prefix)
    }

    /// A node's liveliness token.
    pub fn alive(&self, node: &str) -> String {
        format!("{}/alive/{node}", self.prefix)
    }

    /// Every node's liveliness token.
    pub fn alives(&self) -> String {
        format!("{}/alive/*", self.prefix)
    }

    /// The node name at the end of a `digest/`, `status/` or `alive/` key.
    pub fn node_of<'k>(&self, key: &'k str) -> Option<&'k str> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix('/')?;
        let (_, node) = rest.split_once('/')?;
        check_name(node).ok()?;
        Some(node)
    }

    /// The mapper's map (queryable, `.olm` bytes).
    pub fn map(&self) -> String {
        format!("{}/map", self.prefix)
    }

    /// The mapper's poses (queryable, pose-list text).
    pub fn poses(&self) -> String {
        format!("{}/poses", self.prefix)
    }

    /// Asks the mapper to write its outputs (queryable).
    pub fn write(&self) -> String {
        format!("{}/write", self.prefix)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn record_keys_round_trip_and_odd_keys_are_refused() {
        let k = Keys::new("lab-team_1").unwrap();
        assert_eq!(k.parse_record(&k.record(3, 17)), Some((3, 17)));
        for bad in [
            "olmap/lab-team_1/rec/3",
            "olmap/lab-team_1/rec/03/1",
            "olmap/lab-team_1/rec/3/x",
            "olmap/lab-team_1/rec/3/1/2",
            "olmap/other/rec/3/1",
            "olmap/lab-team_1/rec/99999999999/1",
            "olmap/lab-team_1/rec/1/4294967295",
        ] {
            assert_eq!(k.parse_record(bad), None, "{bad}");
        }
        assert!(Keys::new("a/b").is_err());
        assert!(Keys::new("").is_err());
        assert_eq!(k.node_of(&k.digest("robot0")), Some("robot0"));
    }
}
