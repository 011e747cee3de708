//! 4×4 matrices at file edges. The code holds transforms as glam's `DMat4` (column-major inside); the
//! files insgen reads and writes (`poses.jsonl`, `manifest.json`, COCO image records, Blender job files)
//! hold them as JSON arrays of rows, `m[row][col]`, the order people read matrices in and the one
//! Blender's `mathutils.Matrix` takes. This module is the one place that converts between the two:
//! use it as `#[serde(with = "crate::util::row_major")]` on a `DMat4` field.

use glam::DMat4;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The rows of `m`: `rows(m)[r][c]` is the element in row `r`, column `c`.
pub fn rows(m: &DMat4) -> [[f64; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

/// The matrix whose rows are `rows`.
pub fn from_rows(rows: &[[f64; 4]; 4]) -> DMat4 {
    DMat4::from_cols_array_2d(rows).transpose()
}

/// Serialises `m` as an array of four rows.
///
/// # Errors
/// Whatever the serializer reports.
pub fn serialize<S: Serializer>(m: &DMat4, s: S) -> Result<S::Ok, S::Error> {
    rows(m).serialize(s)
}

/// Reads an array of four rows of four numbers.
///
/// # Errors
/// When the value is not a 4×4 array of numbers.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<DMat4, D::Error> {
    <[[f64; 4]; 4]>::deserialize(d).map(|r| from_rows(&r))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Holder {
        #[serde(with = "super")]
        m: DMat4,
    }

    #[test]
    fn json_holds_rows_and_translation_is_the_last_column() {
        let m = DMat4::from_translation(glam::DVec3::new(1.0, 2.0, 3.0));
        let json = serde_json::to_string(&Holder { m }).unwrap();
        assert_eq!(
            json,
            r#"{"m":[[1.0,0.0,0.0,1.0],[0.0,1.0,0.0,2.0],[0.0,0.0,1.0,3.0],[0.0,0.0,0.0,1.0]]}"#
        );
        let back: Holder = serde_json::from_str(&json).unwrap();
        assert_eq!(back.m, m);
    }

    #[test]
    fn rows_and_from_rows_are_inverse() {
        let r =
            [[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0], [9.0, 10.0, 11.0, 12.0], [13.0, 14.0, 15.0, 16.0]];
        let m = from_rows(&r);
        assert_eq!(m.row(1).to_array(), [5.0, 6.0, 7.0, 8.0]);
        assert_eq!(rows(&m), r);
    }
}
