//! Benchmarks (placeholder module filled by `bench rays`).
