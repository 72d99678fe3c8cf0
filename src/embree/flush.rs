//! Flush-to-zero and denormals-are-zero for the calling thread.
//!
//! Embree's documentation asks every thread that traces rays to set both MXCSR flags: denormal
//! arithmetic is slow and Embree's traversal assumes they are off. Call this from the rayon
//! pool's `start_handler` so every worker has it.

/// Sets FTZ (bit 15) and DAZ (bit 6) in MXCSR on x86-64; a no-op elsewhere.
pub fn flush_denormals_to_zero() {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: `stmxcsr` stores the 32-bit MXCSR register into `csr`, a valid, aligned,
        // writable u32 on our stack; `ldmxcsr` loads it back with only the FTZ/DAZ bits added,
        // which changes no other floating-point behaviour than denormal handling. SSE is always
        // present on x86-64.
        unsafe {
            std::arch::asm!("stmxcsr [{0}]", in(reg) &mut csr as *mut u32, options(nostack));
            csr |= (1 << 15) | (1 << 6);
            std::arch::asm!("ldmxcsr [{0}]", in(reg) &csr as *const u32, options(nostack, readonly));
        }
    }
}
