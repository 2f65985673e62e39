//! Peak resident memory of each stage of `fresco run` (Linux): the kernel's high-water mark
//! `VmHWM` of `/proc/self/status`, reset before each stage by writing 5 to
//! `/proc/self/clear_refs` (proc(5)). Where the reset is refused, the figure is the process's
//! peak since it started and [`PeakMemory::since_start`] says so.

/// A stage's peak memory.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PeakMemory {
    pub bytes: u64,
    /// The high-water mark could not be reset: this is the peak since fresco started.
    pub since_start: bool,
}

/// Resets the high-water mark; false where the system does not allow it.
pub fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", b"5").is_ok()
}

/// The high-water mark of resident memory, bytes.
pub fn peak_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// Measures the peak memory of whatever runs between [`Meter::start`] and [`Meter::stop`].
pub struct Meter {
    reset: bool,
}

impl Meter {
    pub fn start() -> Meter {
        Meter {
            reset: reset_peak(),
        }
    }
    pub fn stop(self) -> Option<PeakMemory> {
        peak_bytes().map(|bytes| PeakMemory {
            bytes,
            since_start: !self.reset,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peak_covers_a_large_allocation_made_during_the_measure() {
        let meter = Meter::start();
        let big = vec![1u8; 64 << 20];
        std::hint::black_box(&big);
        drop(big);
        let peak = meter.stop();
        if cfg!(target_os = "linux") {
            let peak = peak.expect("Linux reports VmHWM");
            assert!(peak.bytes >= 64 << 20, "{peak:?}");
        }
    }
}
