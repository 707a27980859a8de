use std::fmt::Debug;

/// Run-time tag of a voxel type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VoxelType {
    /// `u8`
    U8,
    /// `i8`
    I8,
    /// `u16`
    U16,
    /// `i16`
    I16,
    /// `u32`
    U32,
    /// `i32`
    I32,
    /// `f32`
    F32,
    /// `f64`
    F64,
}

impl VoxelType {
    /// Every supported type, smallest first.
    pub const ALL: [VoxelType; 8] = [
        Self::U8,
        Self::I8,
        Self::U16,
        Self::I16,
        Self::U32,
        Self::I32,
        Self::F32,
        Self::F64,
    ];

    /// Size of one voxel in bytes.
    #[must_use]
    pub const fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// Rust-style name: `u8`, `i16`, `f32`, …
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::U8 => "u8",
            Self::I8 => "i8",
            Self::U16 => "u16",
            Self::I16 => "i16",
            Self::U32 => "u32",
            Self::I32 => "i32",
            Self::F32 => "f32",
            Self::F64 => "f64",
        }
    }

    /// Parse a name as printed by [`VoxelType::name`] (also accepts `uint8`, `int16`,
    /// `float`, `double`, …).
    #[must_use]
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s.to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => Self::U8,
            "i8" | "int8" | "char" => Self::I8,
            "u16" | "uint16" | "ushort" => Self::U16,
            "i16" | "int16" | "short" => Self::I16,
            "u32" | "uint32" | "uint" => Self::U32,
            "i32" | "int32" | "int" => Self::I32,
            "f32" | "float32" | "float" => Self::F32,
            "f64" | "float64" | "double" => Self::F64,
            _ => return None,
        })
    }

    /// `true` for `f32` and `f64`.
    #[must_use]
    pub const fn is_float(self) -> bool {
        matches!(self, Self::F32 | Self::F64)
    }

    /// Representable range as `(min, max)` in `f64` (finite range for floats).
    #[must_use]
    pub const fn range(self) -> (f64, f64) {
        match self {
            Self::U8 => (0.0, u8::MAX as f64),
            Self::I8 => (i8::MIN as f64, i8::MAX as f64),
            Self::U16 => (0.0, u16::MAX as f64),
            Self::I16 => (i16::MIN as f64, i16::MAX as f64),
            Self::U32 => (0.0, u32::MAX as f64),
            Self::I32 => (i32::MIN as f64, i32::MAX as f64),
            Self::F32 => (f32::MIN as f64, f32::MAX as f64),
            Self::F64 => (f64::MIN, f64::MAX),
        }
    }
}

impl std::fmt::Display for VoxelType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A voxel value type. Implemented for `u8, i8, u16, i16, u32, i32, f32, f64`.
///
/// Conversions: [`Voxel::to_f64`] is exact for every type; [`Voxel::from_f64`] rounds to
/// nearest (ties away from zero) and saturates to the type's range for integer types, maps
/// NaN to 0 for integer types, and is a plain cast for floats.
pub trait Voxel: bytemuck::Pod + Default + PartialOrd + Debug + Send + Sync + 'static {
    /// The run-time tag of this type.
    const TYPE: VoxelType;
    /// Exact conversion to `f64`.
    fn to_f64(self) -> f64;
    /// Conversion to `f32` (rounded for 32-bit integers and `f64`).
    fn to_f32(self) -> f32;
    /// Rounding, saturating conversion from `f64` (see the trait docs).
    fn from_f64(v: f64) -> Self;
    /// Reverse the byte order of one value (for big-endian files).
    #[must_use]
    fn swap_bytes(self) -> Self;
}

macro_rules! int_voxel {
    ($($t:ty => $tag:ident),*) => {$(
        impl Voxel for $t {
            const TYPE: VoxelType = VoxelType::$tag;
            #[inline]
            fn to_f64(self) -> f64 { self as f64 }
            #[inline]
            fn to_f32(self) -> f32 { self as f32 }
            #[inline]
            fn from_f64(v: f64) -> Self { v.round() as $t } // `as` saturates and maps NaN to 0
            #[inline]
            fn swap_bytes(self) -> Self { <$t>::swap_bytes(self) }
        }
    )*};
}
int_voxel!(u8 => U8, i8 => I8, u16 => U16, i16 => I16, u32 => U32, i32 => I32);

impl Voxel for f32 {
    const TYPE: VoxelType = VoxelType::F32;
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn swap_bytes(self) -> Self {
        f32::from_bits(self.to_bits().swap_bytes())
    }
}

impl Voxel for f64 {
    const TYPE: VoxelType = VoxelType::F64;
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline]
    fn swap_bytes(self) -> Self {
        f64::from_bits(self.to_bits().swap_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_f64_rounds_and_saturates() {
        assert_eq!(u8::from_f64(-3.0), 0);
        assert_eq!(u8::from_f64(300.0), 255);
        assert_eq!(u8::from_f64(2.5), 3);
        assert_eq!(i16::from_f64(-2.5), -3);
        assert_eq!(i16::from_f64(f64::NAN), 0);
        assert_eq!(i32::from_f64(1e300), i32::MAX);
        assert_eq!(f32::from_f64(0.1), 0.1f32);
    }

    #[test]
    fn names_parse_back() {
        for t in VoxelType::ALL {
            assert_eq!(VoxelType::parse(t.name()), Some(t));
        }
        assert_eq!(VoxelType::parse("double"), Some(VoxelType::F64));
        assert_eq!(VoxelType::parse("complex"), None);
    }

    #[test]
    fn swap_bytes_is_involution() {
        assert_eq!(1.5f32.swap_bytes().swap_bytes(), 1.5);
        assert_eq!(0x1234u16.swap_bytes(), 0x3412);
        assert_ne!(1.5f64.swap_bytes(), 1.5);
    }
}
