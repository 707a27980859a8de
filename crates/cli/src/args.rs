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

/// Parse a polyline of physical points `"x,y,z;x,y,z;…"` (at least one point).
pub fn points(s: &str) -> anyhow::Result<Vec<glam::DVec3>> {
    s.split(';')
        .filter(|p| !p.trim().is_empty())
        .map(point)
        .collect::<anyhow::Result<Vec<_>>>()
        .and_then(|v| {
            if v.is_empty() {
                bail!("no points in {s:?}; write x,y,z;x,y,z;…")
            }
            Ok(v)
        })
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

/// Largest picture side any command renders.
pub const MAX_PICTURE_SIDE: u32 = 8192;

/// Parse a picture size `WIDTHxHEIGHT` (e.g. `800x600`, `x` or `X`) or one number for a square.
///
/// # Errors
/// If the text is not one or two whole numbers from 1 to [`MAX_PICTURE_SIDE`].
pub fn size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s.split_once(['x', 'X']).unwrap_or((s, s));
    let parse = |t: &str| -> anyhow::Result<u32> {
        let v: u32 = t.trim().parse().with_context(|| {
            format!("picture size `{s}` is not WIDTHxHEIGHT (e.g. 640x480) or one number")
        })?;
        anyhow::ensure!(
            (1..=MAX_PICTURE_SIDE).contains(&v),
            "picture size `{s}`: sides must be 1 to {MAX_PICTURE_SIDE}"
        );
        Ok(v)
    };
    Ok((parse(w)?, parse(h)?))
}

/// Parse an up axis, `y` or `z` (a clap value parser).
///
/// # Errors
/// The message of the render crate for anything else.
pub fn up_axis(s: &str) -> Result<volmorph_render::UpAxis, String> {
    s.parse()
        .map_err(|e: volmorph_render::RenderError| e.to_string())
}

/// Parse a view: `AZIMUTH,ELEVATION` in degrees or a view name, about the `up` axis.
///
/// # Errors
/// If the text is neither (the message lists the names).
pub fn view(s: &str, up: volmorph_render::UpAxis) -> anyhow::Result<volmorph_render::Orbit> {
    Ok(volmorph_render::Orbit::parse(s, up)?)
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

    #[test]
    fn sizes_parse() {
        assert_eq!(size("800x600").unwrap(), (800, 600));
        assert_eq!(size("12X3").unwrap(), (12, 3));
        assert_eq!(size("256").unwrap(), (256, 256));
        for bad in ["0x5", "ax3", "-1x2", "3x", "9000x10", "x"] {
            assert!(size(bad).is_err(), "{bad}");
        }
    }
}
