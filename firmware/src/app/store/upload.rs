//! The upload in progress: what was announced, what has arrived, and the checks on each chunk
//! and on the commit. Pure logic: the store writes the chunks and the header.

use chladni_shared::icd::plan::DeviceLimits;
use chladni_shared::icd::store::{
    CHUNK_STEPS, PlanDigest, PlanName, UploadBegin, UploadChunk, UploadError,
};

use super::layout::PlanRecord;

/// An upload between its begin and its commit.
pub struct Upload {
    /// The slot it will replace.
    pub slot: u8,
    /// The bank its chunks go to (no stored plan uses it).
    pub bank: u8,
    name: PlanName,
    repeat: u16,
    steps: u16,
    crc: u32,
    /// Steps received so far.
    received: u16,
    /// CRC of what was received, step by step.
    digest: PlanDigest,
    /// Length of one run of the steps received, ms.
    once_ms: u64,
}

impl Upload {
    /// Starts an upload of `begin` into `slot`, its steps into `bank`.
    pub fn new(slot: u8, bank: u8, begin: &UploadBegin) -> Self {
        Self {
            slot,
            bank,
            name: begin.name.clone(),
            repeat: begin.repeat,
            steps: begin.steps,
            crc: begin.crc,
            received: 0,
            digest: PlanDigest::new(&begin.name, begin.repeat, begin.steps),
            once_ms: 0,
        }
    }

    /// The number of the next chunk expected.
    fn next_index(&self) -> u16 {
        (self.received as usize).div_ceil(CHUNK_STEPS) as u16
    }

    /// Checks `chunk` against the upload (order, length) and its steps against `limits`;
    /// the chunk number it is stored under if it may be.
    pub fn check(&self, chunk: &UploadChunk, limits: &DeviceLimits) -> Result<u8, UploadError> {
        let next = self.next_index();
        if chunk.index < next {
            return Err(UploadError::Duplicate { index: chunk.index });
        }
        if chunk.index > next {
            return Err(UploadError::OutOfOrder { expected: next, got: chunk.index });
        }
        let expected = (self.steps - self.received).min(CHUNK_STEPS as u16);
        let got = chunk.steps.len() as u16;
        if got != expected || expected == 0 {
            return Err(UploadError::BadChunkLength { index: chunk.index, steps: got, expected });
        }
        for (i, step) in chunk.steps.iter().enumerate() {
            limits.check_step(self.received + i as u16, step).map_err(UploadError::Plan)?;
        }
        Ok(chunk.index as u8)
    }

    /// Takes in a checked chunk of `count` steps lasting `ms` in all, with their postcard bytes
    /// (what the plan CRC covers, as stored: not encoded again); steps received so far.
    pub fn accept(&mut self, count: u16, ms: u64, bytes: &[u8]) -> u16 {
        self.digest.step_bytes(bytes);
        self.once_ms += ms;
        self.received += count;
        self.received
    }

    /// Refuses a commit before every step arrived (the upload goes on).
    pub fn check_complete(&self) -> Result<(), UploadError> {
        if self.received < self.steps {
            return Err(UploadError::Missing { received: self.received, expected: self.steps });
        }
        Ok(())
    }

    /// Ends a complete upload: checks its CRC and its length, and gives the header to store.
    pub fn finish(self, limits: &DeviceLimits) -> Result<PlanRecord, UploadError> {
        let got = self.digest.finish();
        if got != self.crc {
            return Err(UploadError::CrcMismatch { expected: self.crc, got });
        }
        let total_ms = self.once_ms * self.repeat as u64;
        limits.check_total_ms(total_ms).map_err(UploadError::Plan)?;
        Ok(PlanRecord {
            name: self.name,
            repeat: self.repeat,
            steps: self.steps,
            crc: self.crc,
            total_ms,
            bank: self.bank,
        })
    }
}
