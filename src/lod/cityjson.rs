//! (Skeleton: being implemented.)

use std::path::Path;

use super::{LodError, ReadOptions, SourceModel};

pub fn read(path: &Path, _opts: &ReadOptions) -> Result<SourceModel, LodError> {
    Err(LodError::malformed(path, "reader not implemented yet"))
}
