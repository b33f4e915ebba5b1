//! TEMPORARY interface of the plan store (replaced by the real store before this branch lands).
use chladni_shared::icd::link::Refusal;
use chladni_shared::icd::plan::{DeviceLimits, Plan};
use chladni_shared::icd::store::{
    DeviceConfig, PlanPage, PlanRef, PlanSummary, StoreError, UploadBegin, UploadChunk,
};
use embedded_storage_async::nor_flash::NorFlash;

/// The plan store.
pub struct PlanStore<F: NorFlash> {
    _flash: F,
}

const NOT_YET: Refusal = Refusal::Store(StoreError::Flash);

impl<F: NorFlash> PlanStore<F> {
    /// A store over `range` of `flash`.
    pub fn new(flash: F, _range: core::ops::Range<u32>) -> Self {
        Self { _flash: flash }
    }
    /// The stored configuration.
    pub async fn load_config(&mut self) -> DeviceConfig {
        DeviceConfig::DEFAULT
    }
    /// Stores a configuration.
    pub async fn set_config(&mut self, _c: DeviceConfig) -> Result<DeviceConfig, Refusal> {
        Err(NOT_YET)
    }
    /// Begins an upload.
    pub async fn begin(&mut self, _b: UploadBegin, _l: &DeviceLimits) -> Result<u8, Refusal> {
        Err(NOT_YET)
    }
    /// One chunk.
    pub async fn chunk(&mut self, _c: UploadChunk, _l: &DeviceLimits) -> Result<u16, Refusal> {
        Err(NOT_YET)
    }
    /// Commit.
    pub async fn commit(&mut self, _l: &DeviceLimits) -> Result<PlanSummary, Refusal> {
        Err(NOT_YET)
    }
    /// List.
    pub async fn list(&mut self, _from: u8) -> Result<PlanPage, Refusal> {
        Err(NOT_YET)
    }
    /// Delete.
    pub async fn delete(&mut self, _p: &PlanRef) -> Result<PlanSummary, Refusal> {
        Err(NOT_YET)
    }
    /// Load.
    pub async fn load(&mut self, _p: &PlanRef, _out: &mut Plan) -> Result<PlanSummary, Refusal> {
        Err(NOT_YET)
    }
}
