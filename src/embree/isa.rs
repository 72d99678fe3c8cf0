//! Embree's kernel families (ISAs), and which of them this CPU can run.
//!
//! Embree ships one set of traversal and intersection kernels per instruction set and picks
//! the widest the CPU supports. `max_isa=` in the device configuration caps that choice, so a
//! machine with AVX2 can also run (and test) the SSE2, SSE4.2 and AVX kernels. Each family
//! lays out and loads packets differently, which is why alignment bugs show up in one family
//! and not another: the tests run every family the CPU has.
use std::fmt;
use std::str::FromStr;

/// One of Embree 4's kernel families, named as `max_isa=` spells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    Sse2,
    Sse42,
    Avx,
    Avx2,
    /// The AVX-512 "SKX" kernels: F, CD, BW, DQ and VL.
    Avx512,
}

impl Isa {
    /// Every family, narrowest first.
    pub const ALL: [Isa; 5] = [Isa::Sse2, Isa::Sse42, Isa::Avx, Isa::Avx2, Isa::Avx512];

    /// The name Embree's configuration string uses.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Sse2 => "sse2",
            Isa::Sse42 => "sse4.2",
            Isa::Avx => "avx",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// Lanes of the widest packet the family's kernels trace natively: 16 for AVX-512, else 8
    /// (AVX and AVX2 trace 8-wide packets; SSE kernels trace them as two halves of 4). `path`
    /// and `bdpt` use it when no `packet_width` is given: on the Zen 4 development VM, AVX-512
    /// `path` rendered the Cornell box 1.05× faster in 16-wide packets than in 8-wide ones and
    /// `bdpt` 1.07×, while capped at AVX2 16-wide packets were 0.75–0.92× as fast as 8-wide
    /// (`docs/benchmarks.md`).
    pub fn packet_lanes(self) -> u32 {
        if self >= Isa::Avx512 {
            16
        } else {
            8
        }
    }

    /// True if this CPU (and OS) can run the family's kernels.
    pub fn supported_by_cpu(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            match self {
                Isa::Sse2 => is_x86_feature_detected!("sse2"),
                Isa::Sse42 => is_x86_feature_detected!("sse4.2") && is_x86_feature_detected!("popcnt"),
                Isa::Avx => is_x86_feature_detected!("avx"),
                Isa::Avx2 => {
                    is_x86_feature_detected!("avx2")
                        && is_x86_feature_detected!("fma")
                        && is_x86_feature_detected!("bmi1")
                        && is_x86_feature_detected!("bmi2")
                        && is_x86_feature_detected!("lzcnt")
                }
                Isa::Avx512 => {
                    is_x86_feature_detected!("avx512f")
                        && is_x86_feature_detected!("avx512cd")
                        && is_x86_feature_detected!("avx512bw")
                        && is_x86_feature_detected!("avx512dq")
                        && is_x86_feature_detected!("avx512vl")
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }

    /// The families this CPU supports, narrowest first.
    pub fn supported() -> Vec<Isa> {
        Isa::ALL.into_iter().filter(|i| i.supported_by_cpu()).collect()
    }
}

impl fmt::Display for Isa {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The name is not one of [`Isa::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown Embree ISA '{0}' (expected sse2, sse4.2, avx, avx2 or avx512)")]
pub struct UnknownIsa(pub String);

impl FromStr for Isa {
    type Err = UnknownIsa;

    fn from_str(s: &str) -> Result<Isa, UnknownIsa> {
        Isa::ALL.into_iter().find(|i| i.name().eq_ignore_ascii_case(s)).ok_or_else(|| UnknownIsa(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_refused() {
        for isa in Isa::ALL {
            assert_eq!(isa.name().parse::<Isa>(), Ok(isa));
        }
        assert_eq!("AVX2".parse::<Isa>(), Ok(Isa::Avx2));
        assert!("avx3".parse::<Isa>().is_err());
        // Every x86-64 CPU has SSE2, and a CPU with a wider family has the narrower ones.
        let supported = Isa::supported();
        assert_eq!(supported.first(), Some(&Isa::Sse2));
        assert_eq!(supported, Isa::ALL[..supported.len()].to_vec());
    }
}
