//! The maximum path length l_m of Novák et al. (2010), §3.3: with Russian roulette driven by
//! reflectance, a fraction ρ_S^l of paths survives l bounces, so l_m = ⌈log_{ρ_S} c⌉ bounces
//! forcibly terminate about a fraction c of the paths.

/// Fewest bounces ever used (a black scene still needs its direct light).
pub const MIN_PATH_LENGTH: u32 = 1;
/// Most bounces ever used; reached as ρ_S → 1, where log_{ρ_S} c diverges.
pub const MAX_PATH_LENGTH: u32 = 64;

/// l_m for mean reflectance `rho` and admitted truncated fraction `c`, clamped to
/// [`MIN_PATH_LENGTH`, `MAX_PATH_LENGTH`].
pub fn max_path_length(rho: f32, c: f32) -> u32 {
    if rho.is_nan() || c.is_nan() || rho <= 0.0 || c <= 0.0 {
        return MIN_PATH_LENGTH;
    }
    if rho >= 1.0 || c >= 1.0 {
        return if c >= 1.0 { MIN_PATH_LENGTH } else { MAX_PATH_LENGTH };
    }
    let l = (c.ln() / rho.ln()).ceil();
    if l.is_finite() {
        (l as u32).clamp(MIN_PATH_LENGTH, MAX_PATH_LENGTH)
    } else {
        MAX_PATH_LENGTH
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_papers_table_1() {
        // Novák et al. Table 1 (c = 1%): ρ_S → l_m.
        assert_eq!(max_path_length(0.32, 0.01), 5);
        assert_eq!(max_path_length(0.16, 0.01), 3);
        assert_eq!(max_path_length(0.52, 0.01), 8);
        assert_eq!(max_path_length(0.67, 0.01), 12);
        assert_eq!(max_path_length(0.43, 0.01), 6);
        assert_eq!(max_path_length(0.71, 0.01), 14);
    }

    #[test]
    fn clamps_at_the_edges() {
        assert_eq!(max_path_length(0.0, 0.01), MIN_PATH_LENGTH);
        assert_eq!(max_path_length(1e-9, 0.01), MIN_PATH_LENGTH);
        assert_eq!(max_path_length(1.0, 0.01), MAX_PATH_LENGTH);
        assert_eq!(max_path_length(0.999_999, 0.01), MAX_PATH_LENGTH);
        assert_eq!(max_path_length(f32::NAN, 0.01), MIN_PATH_LENGTH);
        assert_eq!(max_path_length(0.5, 1.0), MIN_PATH_LENGTH);
        assert_eq!(max_path_length(0.5, 0.0), MIN_PATH_LENGTH);
        // Monotone in ρ between the clamps.
        let mut last = 0;
        for i in 1..100 {
            let l = max_path_length(i as f32 / 100.0, 0.01);
            assert!(l >= last);
            last = l;
        }
    }
}
