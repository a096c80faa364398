//! The Fleet view's data: the campaigns of a fleet database, per vehicle and in total.
//!
//! The server only knows this trait: whoever starts it (`autoplug dashboard --fleet-db`,
//! `autoplug fleet serve --web`) hands it the fleet database behind it. The calls block
//! (a database query); the server makes them off its event loop, one at a time.

/// Read access to a fleet's campaigns, as JSON for the page.
pub trait FleetData: Send + Sync + std::fmt::Debug {
    /// The fleet in numbers and every campaign with its totals, newest first:
    /// `{"summary": {...}, "campaigns": [...]}`.
    fn overview(&self) -> Result<serde_json::Value, String>;
    /// One campaign with the state of each of its vehicles (`None`: no such campaign):
    /// `{"campaign": {...}, "vehicles": [...]}`.
    fn campaign(&self, id: i64) -> Result<Option<serde_json::Value>, String>;
}
