//! What a technique will hold resident, estimated from its configuration, the scene and the
//! resolution before anything is allocated, so the service can refuse a session that does not
//! fit its memory budget (413, naming the field that sizes it) instead of finding out by
//! running out of memory.
//!
//! Units: bytes. Each estimate multiplies the counts the configuration implies by the sizes of
//! the structures the technique really allocates (`size_of`), in checked arithmetic: a
//! product that overflows is refused like one over the budget. `tests/budgets.rs` checks every
//! estimate against the memory the technique reports after its first tick.
use super::TechniqueError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What a technique holds resident between ticks, as it reports each tick in
/// `TickStats.detail.memory`: bytes per structure (named by the technique) and their total.
/// The film, which every session has, is the engine's and not included.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResidentMemory {
    pub total_bytes: u64,
    pub parts: BTreeMap<String, u64>,
}

impl ResidentMemory {
    /// Sets one structure's bytes and the total.
    pub fn set(&mut self, part: &str, bytes: u64) {
        self.parts.insert(part.to_string(), bytes);
        self.total_bytes = self.parts.values().sum();
    }

    /// One structure's bytes (0 if it has none).
    pub fn part(&self, part: &str) -> u64 {
        self.parts.get(part).copied().unwrap_or(0)
    }
}

/// A technique's resident memory and the configuration field that sizes most of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryEstimate {
    pub bytes: u64,
    pub field: &'static str,
}

/// The sum of `terms` (count, bytes each), or `TooLarge` naming `field` on overflow.
pub fn product_sum(field: &'static str, terms: &[(u64, u64)]) -> Result<MemoryEstimate, TechniqueError> {
    let overflow = || TechniqueError::TooLarge {
        field: field.into(),
        message: "the memory this would need overflows 64 bits".into(),
    };
    let mut bytes = 0u64;
    for &(count, each) in terms {
        bytes = count.checked_mul(each).and_then(|b| b.checked_add(bytes)).ok_or_else(overflow)?;
    }
    Ok(MemoryEstimate { bytes, field })
}

/// Bytes of `T`, as a `u64`.
pub fn size<T>() -> u64 {
    std::mem::size_of::<T>() as u64
}
