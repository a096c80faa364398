//! The data of the dashboard's Fleet view (`autoplug dashboard --fleet-db`, `autoplug fleet
//! serve --web`): the campaigns of a fleet database, in total and per vehicle.

use std::sync::Mutex;

use autoplug_fleet::FleetStore;
use serde_json::{json, Value};

/// A fleet database the page reads: one connection, opened again after a failure (the
/// server restarted, the network dropped).
pub struct FleetPage {
    address: String,
    store: Mutex<Option<FleetStore>>,
}

impl std::fmt::Debug for FleetPage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FleetPage").finish_non_exhaustive()
    }
}

impl FleetPage {
    /// Opens the database at once, so a wrong address is told at the start.
    pub fn open(address: &str) -> Result<Self, String> {
        let store = FleetStore::open(address).map_err(|e| e.to_string())?;
        Ok(Self {
            address: address.to_string(),
            store: Mutex::new(Some(store)),
        })
    }

    /// Where the data is (no credentials).
    pub fn name(&self) -> String {
        self.with_store(|s| Ok(s.name().to_string()))
            .unwrap_or_else(|e| e.to_string())
    }

    fn with_store<T>(
        &self,
        query: impl FnOnce(&mut FleetStore) -> Result<T, autoplug_fleet::StoreError>,
    ) -> Result<T, String> {
        // A panic elsewhere while holding the lock leaves a usable connection or none.
        let mut slot = self.store.lock().unwrap_or_else(|p| p.into_inner());
        let store = match slot.as_mut() {
            Some(store) => store,
            None => slot.insert(FleetStore::open(&self.address).map_err(|e| e.to_string())?),
        };
        query(store).map_err(|e| {
            if matches!(e, autoplug_fleet::StoreError::Db(_)) {
                *slot = None;
            }
            e.to_string()
        })
    }
}

impl Drop for FleetPage {
    /// The synchronous PostgreSQL client runs a runtime of its own to close its
    /// connection, which panics inside another: the web server drops the page last from
    /// its runtime's thread when it stops. The connection is then closed on a thread of
    /// its own.
    fn drop(&mut self) {
        let store = self
            .store
            .get_mut()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        if let Some(store) = store {
            if tokio::runtime::Handle::try_current().is_ok() {
                let _ = std::thread::spawn(move || drop(store)).join();
            }
        }
    }
}

impl autoplug_web::FleetData for FleetPage {
    fn overview(&self) -> Result<Value, String> {
        self.with_store(|store| {
            let summary = store.summary()?;
            let campaigns = store.campaigns()?;
            Ok(json!({ "fleet": store.name(), "summary": summary, "campaigns": campaigns }))
        })
    }

    fn campaign(&self, id: i64) -> Result<Option<Value>, String> {
        self.with_store(|store| {
            let Some(campaign) = store.campaign_by_id(id)? else {
                return Ok(None);
            };
            let vehicles = store.campaign_vehicles(id)?;
            Ok(Some(json!({ "campaign": campaign, "vehicles": vehicles })))
        })
    }
}
