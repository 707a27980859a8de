//! Parsers for argument values shared by several commands.

use anyhow::{Context, bail};

/// Parse `"a,b,c"` into three numbers of type `T`.
pub fn triple<T>(s: &str) -> anyhow::Result<[T; 3]>
where
    T: std::str::FromStr,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("expected three comma-separated values, got {s:?}");
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(
            p.parse::<T>()
                .with_context(|| format!("bad number {p:?} in {s:?}"))?,
        );
    }
    out.try_into()
        .map_err(|_| anyhow::anyhow!("expected three values in {s:?}"))
}

/// Parse a physical point `"x,y,z"` with finite coordinates.
pub fn point(s: &str) -> anyhow::Result<glam::DVec3> {
    let p = glam::DVec3::from_array(triple::<f64>(s)?);
    if !p.is_finite() {
        bail!("point {s:?} is not finite");
    }
    Ok(p)
}

/// Parse `"a,b"` into two `f64`.
pub fn pair(s: &str) -> anyhow::Result<[f64; 2]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 2 {
        bail!("expected two comma-separated numbers, got {s:?}");
    }
    let a = parts[0]
        .parse()
        .with_context(|| format!("bad number in {s:?}"))?;
    let b = parts[1]
        .parse()
        .with_context(|| format!("bad number in {s:?}"))?;
    Ok([a, b])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_triples_and_pairs() {
        assert_eq!(triple::<usize>("1, 2,3").unwrap(), [1, 2, 3]);
        assert!(triple::<usize>("1,2").is_err());
        assert!(triple::<usize>("1,x,3").is_err());
        assert_eq!(pair("40,400").unwrap(), [40.0, 400.0]);
        assert!(pair("40").is_err());
    }
}
