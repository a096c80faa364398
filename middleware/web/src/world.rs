//! The world channel: the simulator's view of the car on its road, for the dashboard's
//! world view. It is a channel of its own beside the live table: the gateway's pipeline
//! knows only the bus and never writes here; the virtual car's loop does (a recording's
//! world file in a replay). Memory is bounded: the road's description and the last
//! [`MAX_POSES`] poses, whatever the number of clients.
//!
//! On the stream a client gets `{"type":"world","description":{…},"poses":[…]}` first
//! when there is a world (the description: road and car, see
//! `autoplug_virtual_car::world::description`; the poses kept so far, for the path and
//! the tyre marks), then, at most every 50 ms and when it changed, a `world` message with
//! the poses published since (and the description again if it changed). A pose is
//! `[t, x, y, heading, speed, steer, marks]` (bus time s, m, rad, m/s, rad, 4 bits FL…RR).

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Poses kept for a client that joins (or falls behind): 2 minutes at 20 Hz.
pub const MAX_POSES: usize = 2400;

/// Longest description accepted, bytes: a 20 km road described every 2 m is about 400 KB.
pub const MAX_DESCRIPTION_BYTES: usize = 1 << 20;

#[derive(Debug, Default)]
struct World {
    /// The description as JSON, and the version that set it.
    description: Option<(String, u64)>,
    /// Poses as JSON arrays, each with its version.
    poses: VecDeque<(String, u64)>,
}

/// The world channel (see the module docs).
#[derive(Debug, Default)]
pub struct WorldChannel {
    world: Mutex<World>,
    /// Bumped by every change; clients compare it with the last they sent.
    version: AtomicU64,
}

/// Where a client is in the channel: the versions of the description and the last pose
/// it was sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WorldCursor {
    description: u64,
    pose: u64,
}

impl WorldChannel {
    /// An empty channel (no world: the bus is not a virtual car's).
    pub fn new() -> Self {
        Self::default()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, World> {
        // A panic elsewhere while holding the lock leaves valid data: go on with it.
        self.world.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The world's description (road and car) becomes `json`; the poses start over (they
    /// belong to the old world). Refused, with the reason, when larger than
    /// [`MAX_DESCRIPTION_BYTES`].
    pub fn describe(&self, json: String) -> Result<(), String> {
        if json.len() > MAX_DESCRIPTION_BYTES {
            return Err(format!(
                "the world's description is {} bytes; at most {MAX_DESCRIPTION_BYTES}",
                json.len()
            ));
        }
        let mut world = self.lock();
        let version = self.version.fetch_add(1, Ordering::SeqCst) + 1;
        world.description = Some((json, version));
        world.poses.clear();
        Ok(())
    }

    /// Whether the world has been described.
    pub fn is_described(&self) -> bool {
        self.lock().description.is_some()
    }

    /// Publishes a pose (a JSON array, as the module docs say); the oldest goes beyond
    /// [`MAX_POSES`].
    pub fn publish(&self, pose_json: String) {
        let mut world = self.lock();
        let version = self.version.fetch_add(1, Ordering::SeqCst) + 1;
        if world.poses.len() == MAX_POSES {
            world.poses.pop_front();
        }
        world.poses.push_back((pose_json, version));
    }

    /// The channel's version: it changes whenever something is described or published.
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::SeqCst)
    }

    /// What a reader at `cursor` has not had: the description if it is not the one the
    /// reader had, and the poses after its last (all the kept ones with a new
    /// description); and its new cursor. `None` when there is no world.
    pub fn take_since(&self, cursor: WorldCursor) -> Option<WorldNews> {
        let world = self.lock();
        let (description, described) = world.description.as_ref()?;
        let fresh = *described != cursor.description;
        let after = if fresh { 0 } else { cursor.pose };
        let poses: Vec<String> = world
            .poses
            .iter()
            .filter(|(_, v)| *v > after)
            .map(|(pose, _)| pose.clone())
            .collect();
        let last = world.poses.back().map_or(after, |(_, v)| (*v).max(after));
        Some(WorldNews {
            description: fresh.then(|| description.clone()),
            poses,
            cursor: WorldCursor {
                description: *described,
                pose: last,
            },
        })
    }

    /// The `world` message for a client at `cursor` (the description if it has not had
    /// this one, and the poses after its last), and its new cursor; `None` when there is
    /// nothing new for it (or no world).
    pub fn message_since(&self, cursor: WorldCursor) -> Option<(String, WorldCursor)> {
        let news = self.take_since(cursor)?;
        if news.description.is_none() && news.poses.is_empty() {
            return None;
        }
        let size = news.poses.iter().map(|p| p.len() + 1).sum::<usize>();
        let mut json =
            String::with_capacity(64 + size + news.description.as_ref().map_or(0, String::len));
        json.push_str("{\"type\":\"world\"");
        if let Some(description) = &news.description {
            let _ = write!(json, ",\"description\":{description}");
        }
        json.push_str(",\"poses\":[");
        for (i, pose) in news.poses.iter().enumerate() {
            if i > 0 {
                json.push(',');
            }
            json.push_str(pose);
        }
        json.push_str("]}");
        Some((json, news.cursor))
    }
}

/// What [`WorldChannel::take_since`] hands a reader.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldNews {
    /// The description, when the reader has not had it.
    pub description: Option<String>,
    /// The poses it has not had, oldest first.
    pub poses: Vec<String>,
    /// Where the reader is now.
    pub cursor: WorldCursor,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(json: &str) -> serde_json::Value {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn a_client_gets_the_world_then_only_what_is_new() {
        let world = WorldChannel::new();
        assert!(
            world.message_since(WorldCursor::default()).is_none(),
            "no world yet"
        );
        world.publish("[0.0,0,0,0,0,0,0]".into());
        assert!(
            world.message_since(WorldCursor::default()).is_none(),
            "not described"
        );
        world.describe(r#"{"road":null}"#.into()).unwrap();
        world.publish("[0.05,1,0,0,20,0,0]".into());
        world.publish("[0.10,2,0,0,20,0,3]".into());
        let (first, cursor) = world.message_since(WorldCursor::default()).unwrap();
        let first = parse(&first);
        assert_eq!(first["type"], "world");
        assert_eq!(first["description"]["road"], serde_json::Value::Null);
        assert_eq!(first["poses"].as_array().unwrap().len(), 2, "{first}");
        assert!(world.message_since(cursor).is_none(), "nothing new");
        world.publish("[0.15,3,0,0,20,0,0]".into());
        let (next, cursor) = world.message_since(cursor).unwrap();
        let next = parse(&next);
        assert!(next.get("description").is_none(), "{next}");
        assert_eq!(next["poses"][0][1], 3);
        // A new world (a replay of another road): the description and its poses again.
        world.describe(r#"{"road":{"name":"b"}}"#.into()).unwrap();
        let (again, _) = world.message_since(cursor).unwrap();
        let again = parse(&again);
        assert_eq!(again["description"]["road"]["name"], "b");
        assert_eq!(again["poses"].as_array().unwrap().len(), 0);
    }

    #[test]
    fn memory_is_bounded_whatever_is_published() {
        let world = WorldChannel::new();
        world.describe("{}".into()).unwrap();
        for i in 0..(MAX_POSES + 500) {
            world.publish(format!("[{i},0,0,0,0,0,0]"));
        }
        let (all, _) = world.message_since(WorldCursor::default()).unwrap();
        let all = parse(&all);
        let poses = all["poses"].as_array().unwrap();
        assert_eq!(poses.len(), MAX_POSES);
        assert_eq!(poses[0][0], 500, "the oldest went first");
        let huge = "x".repeat(MAX_DESCRIPTION_BYTES + 1);
        let refused = world.describe(huge).unwrap_err();
        assert!(refused.contains("at most"), "{refused}");
    }
}
