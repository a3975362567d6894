//! The memory budget: work whose size follows from its input (a raster's
//! declared size, a target grid, an image) is estimated before anything is
//! allocated, and refused with the size, the budget and the option to
//! change when it would not fit — an allocation failure must never reach
//! the allocator's abort. The budget defaults to the memory the machine has
//! available; `--max-memory` sets it. Either way it never exceeds what the
//! process may still take under its own limits: the address-space limit
//! (`ulimit -v`) less what it has mapped, and its cgroup's `memory.max`
//! (a container's or a batch job's) less what the cgroup uses.

use crate::{Error, Result};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The budget in bytes; 0 until set or first read.
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// Budget used where the machine's available memory cannot be read.
const FALLBACK_BYTES: u64 = 4 << 30;

/// Set the budget for this process, bytes (lowered to the process's limits).
pub fn set_budget(bytes: u64) {
    BUDGET.store(bytes.min(process_headroom()).max(1), Ordering::Relaxed);
}

/// The budget: as set, else the machine's available memory (Linux's
/// `MemAvailable`), else 4 GiB — in each case at most the process's
/// headroom under its limits.
pub fn budget() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => {
            let bytes = available_bytes()
                .unwrap_or(FALLBACK_BYTES)
                .min(process_headroom())
                .max(1);
            BUDGET.store(bytes, Ordering::Relaxed);
            bytes
        }
        b => b,
    }
}

/// `MemAvailable` from `/proc/meminfo`, bytes.
fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    kib_field(&text, "MemAvailable:")
}

/// What this process may still allocate under its address-space limit and
/// its cgroup's memory limit, bytes (`u64::MAX` where neither is set).
fn process_headroom() -> u64 {
    let address_space = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|limits| address_space_limit(&limits))
        .map_or(u64::MAX, |limit| {
            let mapped = std::fs::read_to_string("/proc/self/status")
                .ok()
                .and_then(|status| kib_field(&status, "VmSize:"))
                .unwrap_or(0);
            limit.saturating_sub(mapped)
        });
    let cgroup = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|text| cgroup_headroom(&text, Path::new("/sys/fs/cgroup")))
        .unwrap_or(u64::MAX);
    address_space.min(cgroup)
}

/// The soft "Max address space" of `/proc/self/limits`, bytes; `None` when
/// unlimited.
fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The least headroom (`memory.max` − `memory.current`) over the cgroup v2
/// folder named in `/proc/self/cgroup` (`0::/PATH`) and every folder above
/// it, under `root`; `None` when no level sets a limit.
fn cgroup_headroom(proc_cgroup: &str, root: &Path) -> Option<u64> {
    let relative = proc_cgroup.lines().find_map(|l| l.strip_prefix("0::"))?;
    let mut dir = root.join(relative.trim_start_matches('/'));
    let mut least: Option<u64> = None;
    while dir.starts_with(root) {
        let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok();
        let max = read("memory.max").and_then(|t| t.trim().parse::<u64>().ok());
        if let Some(max) = max {
            let used = read("memory.current")
                .and_then(|t| t.trim().parse::<u64>().ok())
                .unwrap_or(0);
            least = Some(least.unwrap_or(u64::MAX).min(max.saturating_sub(used)));
        }
        if !dir.pop() {
            break;
        }
    }
    least
}

/// A `NAME: VALUE kB` field of a /proc file, bytes.
fn kib_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line[name.len()..].split_whitespace().next()?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// Refuse `what` when it needs more than the budget: `count` items of
/// `item_bytes` each (saturating, so absurd sizes are refused, not
/// wrapped). `change` says which option or input would make it smaller.
pub fn check(what: &str, count: u64, item_bytes: u64, change: &str) -> Result<()> {
    let needed = count.saturating_mul(item_bytes);
    let limit = budget();
    if needed > limit {
        return Err(Error::Input(format!(
            "{what} needs about {} but the memory budget is {} \
             (raise it with --max-memory, or {change})",
            human(needed),
            human(limit)
        )));
    }
    Ok(())
}

/// Parse a size such as `512M`, `4G`, `1.5G` or a plain number of bytes
/// (K, M, G, T are powers of 1024).
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let (number, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, ""),
    };
    let scale: u64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => return Err(format!("{text:?}: expected a size such as 512M or 4G")),
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("{text:?}: expected a size such as 512M or 4G"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{text:?}: the size must be positive"));
    }
    Ok((value * scale as f64).min(u64::MAX as f64) as u64)
}

/// Bytes in the largest binary unit that keeps a number ≥ 1.
pub fn human(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(parse_size("512M"), Ok(512 << 20));
        assert_eq!(parse_size("4G"), Ok(4 << 30));
        assert_eq!(parse_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_size("1000"), Ok(1000));
        assert!(parse_size("-1G").is_err() && parse_size("lots").is_err());
        assert!(parse_size("4X").is_err() && parse_size("nanG").is_err());
        assert_eq!(human(3 << 29), "1.5 GiB");
        assert_eq!(human(12), "12 B");
    }

    #[test]
    fn work_over_the_budget_is_refused_with_the_sizes() {
        set_budget(1 << 30);
        assert!(check("a grid", 1 << 20, 8, "crop it").is_ok());
        let message = check("a 300000×300000 grid", 300_000 * 300_000, 8, "pass --te")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("670.6 GiB")
                && message.contains("1.0 GiB")
                && message.contains("--max-memory")
                && message.contains("pass --te"),
            "{message}"
        );
        // Sizes beyond u64 saturate rather than wrap to something small.
        assert!(check("absurd", u64::MAX, 8, "no").is_err());
    }

    #[test]
    fn the_process_limits_are_read() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units\n\
                      Max stack size            8388608              unlimited            bytes\n\
                      Max address space         6442450944           unlimited            bytes\n";
        assert_eq!(address_space_limit(limits), Some(6 << 30));
        assert_eq!(
            address_space_limit(&limits.replace("6442450944", "unlimited")),
            None
        );
        assert_eq!(kib_field("VmSize:\t  2048 kB\n", "VmSize:"), Some(2 << 20));

        // A job's cgroup at 3 GiB using 1 GiB, under a parent at 8 GiB.
        let root = tempfile::tempdir().unwrap();
        let job = root.path().join("slurm/job_7");
        std::fs::create_dir_all(&job).unwrap();
        std::fs::write(root.path().join("slurm/memory.max"), "8589934592\n").unwrap();
        std::fs::write(job.join("memory.max"), "3221225472\n").unwrap();
        std::fs::write(job.join("memory.current"), "1073741824\n").unwrap();
        let at = |text: &str| cgroup_headroom(text, root.path());
        assert_eq!(at("0::/slurm/job_7\n"), Some(2 << 30));
        std::fs::write(job.join("memory.max"), "max\n").unwrap();
        assert_eq!(at("0::/slurm/job_7\n"), Some(8 << 30));
        assert_eq!(at("1:name=systemd:/\n"), None);
        assert!(process_headroom() > 0);
    }
}
