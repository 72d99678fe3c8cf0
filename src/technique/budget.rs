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
