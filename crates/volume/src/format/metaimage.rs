//! Placeholder: the metaimage reader and writer are being written.

use std::path::Path;

use super::{Header, WriteOptions};
use crate::{AnyVolume, VolumeError};

pub(crate) fn read(_path: &Path) -> Result<(AnyVolume, Header), VolumeError> {
    Err(VolumeError::Unsupported("metaimage reading".into()))
}

pub(crate) fn write(_p: &Path, _v: &AnyVolume, _o: &WriteOptions) -> Result<(), VolumeError> {
    Err(VolumeError::Unsupported("metaimage writing".into()))
}
