//! The memory budget: one limit on the bytes any single allocation sized from user input may
//! take, checked *before* allocating.
//!
//! Every size that comes from a file, an option or a parameter (volume dims, grid sizes,
//! lattice control-point counts, handle counts, decompressed lengths, picture sizes) goes
//! through [`check_bytes`] (or [`checked_len`](crate::checked_len), [`try_vec`]) so that an
//! impossible request becomes an [`crate::IoError::Budget`] naming what was
//! asked for, instead of an abort in the allocator.
//!
//! The limit is, in order of precedence:
//! 1. the value given to [`set_memory_limit`] (the command-line option `--memory-limit`);
//! 2. the environment variable [`MEMORY_LIMIT_ENV`] (`VOLMORPH_MEMORY_LIMIT`);
//! 3. [`DEFAULT_MEMORY_FRACTION`] of the physical memory available to the process (the
//!    smaller of `MemTotal` in `/proc/meminfo` and a cgroup v2/v1 memory limit), or
//!    [`FALLBACK_MEMORY_BYTES`] where physical memory cannot be read.
//!
//! Limits are written as a byte count with an optional binary suffix (`512M`, `8G`, `1.5GiB`,
//! `2T`) or as a percentage of physical memory (`50%`). Physical memory is read from `/proc`
//! by hand because it is a few lines and a system-information crate would pull in far more
//! than this needs.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::IoError;

/// Environment variable that sets the memory budget (see [`parse_limit`] for the syntax).
pub const MEMORY_LIMIT_ENV: &str = "VOLMORPH_MEMORY_LIMIT";

/// Fraction of physical memory used as the default budget. A single array larger than
/// three quarters of the machine leaves no room for the input it is computed from; below
/// that, the operating system and the other buffers of a command still fit.
pub const DEFAULT_MEMORY_FRACTION: f64 = 0.75;

/// Budget used when physical memory cannot be determined: 8 GiB, what a small workstation
/// holds.
pub const FALLBACK_MEMORY_BYTES: u64 = 8 << 30;

/// Smallest budget accepted: 1 MiB. Below that no command can read even a header.
pub const MIN_MEMORY_BYTES: u64 = 1 << 20;

/// 0 = not set by [`set_memory_limit`].
static OVERRIDE: AtomicU64 = AtomicU64::new(0);
static FROM_ENV: OnceLock<Result<Option<u64>, String>> = OnceLock::new();

/// Set the budget for the rest of the process (the command-line option), in bytes.
/// Values below [`MIN_MEMORY_BYTES`] are raised to it.
pub fn set_memory_limit(bytes: u64) {
    OVERRIDE.store(bytes.max(MIN_MEMORY_BYTES), Ordering::Relaxed);
}

/// The current budget in bytes (see the module documentation for where it comes from).
///
/// A malformed [`MEMORY_LIMIT_ENV`] is ignored here (the default applies); front-ends call
/// [`memory_limit_from_env`] at start-up to report it.
#[must_use]
pub fn memory_limit() -> u64 {
    let o = OVERRIDE.load(Ordering::Relaxed);
    if o != 0 {
        return o;
    }
    match env_limit() {
        Ok(Some(b)) => b,
        _ => default_limit(),
    }
}

/// The budget set by [`MEMORY_LIMIT_ENV`], if any.
///
/// # Errors
/// [`IoError::Size`] naming the variable when its value cannot be parsed.
pub fn memory_limit_from_env() -> Result<Option<u64>, IoError> {
    env_limit().map_err(|e| IoError::Size(format!("{MEMORY_LIMIT_ENV}: {e}")))
}

fn env_limit() -> Result<Option<u64>, String> {
    FROM_ENV
        .get_or_init(|| match std::env::var(MEMORY_LIMIT_ENV) {
            Ok(v) if !v.trim().is_empty() => parse_limit(&v).map(Some),
            _ => Ok(None),
        })
        .clone()
}

/// [`DEFAULT_MEMORY_FRACTION`] of physical memory, or [`FALLBACK_MEMORY_BYTES`].
#[must_use]
pub fn default_limit() -> u64 {
    physical_memory().map_or(FALLBACK_MEMORY_BYTES, |m| {
        ((m as f64 * DEFAULT_MEMORY_FRACTION) as u64).max(MIN_MEMORY_BYTES)
    })
}

/// Physical memory available to this process in bytes: the smaller of the machine's total
/// and the cgroup's memory limit, where they can be read (Linux); `None` elsewhere.
#[must_use]
pub fn physical_memory() -> Option<u64> {
    static MEM: OnceLock<Option<u64>> = OnceLock::new();
    *MEM.get_or_init(|| {
        let total = std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|s| meminfo_total(&s));
        let cgroup = [
            "/sys/fs/cgroup/memory.max",
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
        ]
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok())
        .and_then(|s| s.trim().parse::<u64>().ok());
        match (total, cgroup) {
            (Some(t), Some(c)) => Some(t.min(c)),
            (t, c) => t.or(c),
        }
    })
}

fn meminfo_total(s: &str) -> Option<u64> {
    let line = s.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_ascii_whitespace().nth(1)?.parse().ok()?;
    kb.checked_mul(1024)
}

/// Parse a memory limit: a byte count with an optional suffix `K`, `M`, `G`, `T` (binary
/// multiples; `KB`/`KiB` etc. are accepted too, case-insensitive), or a percentage of
/// physical memory (`50%`).
///
/// # Errors
/// A message saying what is wrong with `s` (not a number, not positive, not finite, more
/// than 100 %).
pub fn parse_limit(s: &str) -> Result<u64, String> {
    let t = s.trim();
    if let Some(p) = t.strip_suffix('%') {
        let f: f64 = p
            .trim()
            .parse()
            .map_err(|_| format!("`{t}` is not a percentage"))?;
        if !(f > 0.0 && f <= 100.0) {
            return Err(format!("`{t}`: a percentage must be in (0, 100]"));
        }
        let mem = physical_memory().unwrap_or(FALLBACK_MEMORY_BYTES);
        return Ok(((mem as f64 * f / 100.0) as u64).max(MIN_MEMORY_BYTES));
    }
    let lower = t.to_ascii_lowercase();
    let digits_end = lower
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '+'))
        .unwrap_or(lower.len());
    let (num, unit) = lower.split_at(digits_end);
    let scale: u64 = match unit.trim() {
        "" | "b" => 1,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        "t" | "tb" | "tib" => 1 << 40,
        u => return Err(format!("`{t}`: unknown unit `{u}` (use K, M, G or T)")),
    };
    let v: f64 = num
        .parse()
        .map_err(|_| format!("`{t}` is not a size such as 8G or 512M"))?;
    let bytes = v * scale as f64;
    if !(bytes.is_finite() && bytes >= 1.0) {
        return Err(format!("`{t}`: a size must be positive"));
    }
    Ok((bytes.min(u64::MAX as f64) as u64).max(MIN_MEMORY_BYTES))
}

/// A byte count in binary units for messages (`1.50 GiB`, `512 MiB`, `100 B`).
#[must_use]
pub fn human_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["KiB", "MiB", "GiB", "TiB", "PiB"];
    if b < 1024 {
        return format!("{b} B");
    }
    let mut v = b as f64;
    let mut unit = "B";
    for u in UNITS {
        if v < 1024.0 {
            break;
        }
        v /= 1024.0;
        unit = u;
    }
    if v >= 100.0 {
        format!("{v:.0} {unit}")
    } else {
        format!("{v:.2} {unit}")
    }
}

/// An `f64` for messages: ordinary notation for magnitudes from 1e-4 to 1e9 (and 0), `{:e}`
/// notation beyond, so that a value such as 1e308 prints as `1e308`, not as 309 digits.
/// Non-finite values print as `NaN`, `inf`, `-inf`. A precision applies in either notation
/// (`{:.4}`: `0.1235`, `1.0000e300`), so a message may ask for a fixed number of digits and
/// still stay short.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        let a = x.abs();
        let ordinary = !x.is_finite() || x == 0.0 || (1e-4..1e9).contains(&a);
        match (ordinary, f.precision()) {
            (true, None) => write!(f, "{x}"),
            (true, Some(p)) => write!(f, "{x:.p$}"),
            (false, None) => write!(f, "{x:e}"),
            (false, Some(p)) => write!(f, "{x:.p$e}"),
        }
    }
}

/// Several `f64`s for messages (a point, a vector, a matrix column) as `[a, b, c]`, each in
/// [`Num`]'s notation and with the precision given, if any (`{:.4}`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nums<'a>(pub &'a [f64]);

impl std::fmt::Display for Nums<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("[")?;
        for (i, &x) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            match f.precision() {
                Some(p) => write!(f, "{:.p$}", Num(x))?,
                None => write!(f, "{}", Num(x))?,
            }
        }
        f.write_str("]")
    }
}

/// Check that `bytes` (needed for `what`, e.g. "a 2000³ f32 grid") fit the budget.
///
/// # Errors
/// [`IoError::Budget`] naming `what`, the size and the limit, and how to raise it.
pub fn check_bytes(what: &str, bytes: u64) -> Result<(), IoError> {
    let limit = memory_limit();
    if bytes > limit {
        return Err(IoError::Budget {
            what: what.to_string(),
            bytes,
            limit,
        });
    }
    Ok(())
}

/// Check `count` elements of `elem_size` bytes against the budget; returns the byte count.
///
/// # Errors
/// [`IoError::Size`] on overflow, [`IoError::Budget`] beyond the budget.
pub fn check_elems(what: &str, count: u64, elem_size: u64) -> Result<u64, IoError> {
    let bytes = count.checked_mul(elem_size).ok_or_else(|| {
        IoError::Size(format!(
            "{what}: {count} elements of {elem_size} bytes overflow"
        ))
    })?;
    check_bytes(what, bytes)?;
    Ok(bytes)
}

/// A vector of `n` copies of `value`, after checking `n` elements against the budget and
/// reserving with [`Vec::try_reserve_exact`], so neither a huge request nor an allocator
/// failure aborts the process.
///
/// # Errors
/// [`IoError::Budget`] beyond the budget; [`IoError::Alloc`] when the allocator refuses.
pub fn try_vec<T: Clone>(what: &str, n: usize, value: T) -> Result<Vec<T>, IoError> {
    let mut v = try_with_capacity(what, n)?;
    v.resize(n, value);
    Ok(v)
}

/// An empty vector with room for `n` elements, checked as [`try_vec`].
///
/// # Errors
/// As [`try_vec`].
pub fn try_with_capacity<T>(what: &str, n: usize) -> Result<Vec<T>, IoError> {
    let bytes = check_elems(what, n as u64, std::mem::size_of::<T>() as u64)?;
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| IoError::Alloc {
        what: what.to_string(),
        bytes,
    })?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_parse_with_units_and_percentages() {
        assert_eq!(parse_limit("512M").unwrap(), 512 << 20);
        assert_eq!(parse_limit("8g").unwrap(), 8 << 30);
        assert_eq!(parse_limit("1.5GiB").unwrap(), 3 << 29);
        assert_eq!(parse_limit(" 2 TB ").unwrap(), 2 << 40);
        assert_eq!(parse_limit("4194304").unwrap(), 4 << 20);
        // Tiny values are raised to the minimum.
        assert_eq!(parse_limit("10").unwrap(), MIN_MEMORY_BYTES);
        let half = parse_limit("50%").unwrap();
        let mem = physical_memory().unwrap_or(FALLBACK_MEMORY_BYTES);
        assert!(half.abs_diff(mem / 2) <= 1, "{half} vs {mem}");
        for bad in ["", "x", "-1G", "0", "12Q", "150%", "0%", "nan", "inf"] {
            assert!(parse_limit(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn meminfo_is_read() {
        let s = "MemTotal:       24576000 kB\nMemFree: 1 kB\n";
        assert_eq!(meminfo_total(s), Some(24_576_000 * 1024));
        assert_eq!(meminfo_total("nothing"), None);
    }

    /// 1e308 was printed as a 309-digit number, giving 1 KB error lines.
    #[test]
    fn numbers_past_1e9_printed_with_309_digits() {
        assert_eq!(Num(1e308).to_string(), "1e308");
        assert_eq!(Num(-2.5e12).to_string(), "-2.5e12");
        assert_eq!(Num(1e-300).to_string(), "1e-300");
        assert_eq!(Num(123456.5).to_string(), "123456.5");
        assert_eq!(Num(0.25).to_string(), "0.25");
        assert_eq!(Num(0.0).to_string(), "0");
        assert_eq!(Num(f64::NAN).to_string(), "NaN");
        assert_eq!(Num(f64::NEG_INFINITY).to_string(), "-inf");
        // A precision applies in both notations.
        assert_eq!(format!("{:.4}", Num(0.123_456)), "0.1235");
        assert_eq!(format!("{:.4}", Num(1e300)), "1.0000e300");
        assert_eq!(format!("{:.2}", Num(f64::NAN)), "NaN");
        assert_eq!(
            format!("{:.3}", Nums(&[1.0, -1e300, 2.5e-7])),
            "[1.000, -1.000e300, 2.500e-7]"
        );
        assert_eq!(
            Nums(&[0.5, 1e20, f64::INFINITY]).to_string(),
            "[0.5, 1e20, inf]"
        );
        assert_eq!(Nums(&[]).to_string(), "[]");
    }

    #[test]
    fn human_bytes_are_short() {
        assert_eq!(human_bytes(100), "100 B");
        assert_eq!(human_bytes(1536), "1.50 KiB");
        assert_eq!(human_bytes(32 << 30), "32.00 GiB");
        assert_eq!(human_bytes(300 << 30), "300 GiB");
    }

    #[test]
    fn default_budget_is_a_fraction_of_physical_memory() {
        let d = default_limit();
        match physical_memory() {
            Some(m) => assert!(d <= m && d as f64 >= 0.7 * m as f64, "{d} of {m}"),
            None => assert_eq!(d, FALLBACK_MEMORY_BYTES),
        }
    }

    #[test]
    fn requests_beyond_the_budget_are_refused_before_allocating() {
        // 2^60 bytes exceeds any budget; the error names what was asked for.
        let e = try_vec::<u8>("a test grid", 1 << 60, 0).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("a test grid") && msg.contains(MEMORY_LIMIT_ENV),
            "{msg}"
        );
        assert!(matches!(e, IoError::Budget { .. }));
        assert!(check_elems("x", u64::MAX, 8).is_err());
        assert_eq!(try_vec("small", 4, 7u16).unwrap(), vec![7; 4]);
    }
}
