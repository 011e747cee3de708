//! Per-feature properties insgen uses (identity, LoD, measured height), taken from a b3dm batch table
//! or an `EXT_structural_metadata` property table by the property names listed here.

/// Properties holding the building identity, tried in order. PLATEAU and most CityGML converters
/// write `gml_id`.
pub const ID_PROPERTIES: &[&str] = &["gml_id", "gml:id", "gmlId", "gmlid"];

/// Properties holding the LoD the geometry was made from, tried in order. PLATEAU's FME export
/// stores it as `_lod` (a BYTE in the binary body: 1 or 2).
pub const LOD_PROPERTIES: &[&str] = &["_lod", "lod", "LoD", "LOD", "uro:lod"];

/// Properties holding the measured building height in metres, tried in order. Values that are not
/// finite and positive (PLATEAU writes −9999 for "unknown") are ignored.
pub const HEIGHT_PROPERTIES: &[&str] =
    &["bldg:measuredHeight", "measuredHeight", "measured_height", "measuredheight", "height"];

/// One value of a property column.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum PropValue {
    Null,
    Num(f64),
    Str(String),
}

impl PropValue {
    /// A JSON value as a property value (objects, arrays and booleans are not used: `Null`).
    pub(crate) fn from_json(v: &serde_json::Value) -> PropValue {
        match v {
            serde_json::Value::String(s) => PropValue::Str(s.clone()),
            serde_json::Value::Number(n) => n.as_f64().map_or(PropValue::Null, PropValue::Num),
            _ => PropValue::Null,
        }
    }

    /// As text: strings as they are, integers without a decimal point, other numbers in shortest form.
    pub(crate) fn as_text(&self) -> Option<String> {
        match self {
            PropValue::Null => None,
            PropValue::Str(s) if s.is_empty() => None,
            PropValue::Str(s) => Some(s.clone()),
            PropValue::Num(x) if x.fract() == 0.0 && x.abs() < 1e15 => Some(format!("{}", *x as i64)),
            PropValue::Num(x) => Some(format!("{x}")),
        }
    }

    /// As a height in metres: finite and > 0 (numbers, or strings that parse as numbers).
    pub(crate) fn as_height_m(&self) -> Option<f64> {
        let x = match self {
            PropValue::Num(x) => *x,
            PropValue::Str(s) => s.trim().parse::<f64>().ok()?,
            PropValue::Null => return None,
        };
        (x.is_finite() && x > 0.0).then_some(x)
    }
}

/// What insgen keeps of one feature's properties.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct FeatureProps {
    pub id: Option<String>,
    pub lod: Option<String>,
    pub measured_height_m: Option<f64>,
}

/// Builds per-feature properties for `count` features from a column lookup (`column(name)` returns
/// the property's values, or `None` when the table has no such property).
///
/// # Errors
/// Whatever `column` returns for a property that exists but cannot be read.
pub(crate) fn feature_props<E>(
    count: usize,
    mut column: impl FnMut(&str) -> Result<Option<Vec<PropValue>>, E>,
) -> Result<Vec<FeatureProps>, E> {
    let mut first_column = |names: &[&str]| -> Result<Option<Vec<PropValue>>, E> {
        for name in names {
            if let Some(values) = column(name)? {
                return Ok(Some(values));
            }
        }
        Ok(None)
    };
    let ids = first_column(ID_PROPERTIES)?;
    let lods = first_column(LOD_PROPERTIES)?;
    let heights = first_column(HEIGHT_PROPERTIES)?;
    let at = |col: &Option<Vec<PropValue>>, i: usize| col.as_ref().and_then(|c| c.get(i)).cloned();
    Ok((0..count)
        .map(|i| FeatureProps {
            id: at(&ids, i).and_then(|v| v.as_text()),
            lod: at(&lods, i).and_then(|v| v.as_text()),
            measured_height_m: at(&heights, i).and_then(|v| v.as_height_m()),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_forms() {
        assert_eq!(PropValue::Num(2.0).as_text().as_deref(), Some("2"));
        assert_eq!(PropValue::Num(2.2).as_text().as_deref(), Some("2.2"));
        assert_eq!(PropValue::Str("bldg_1".into()).as_text().as_deref(), Some("bldg_1"));
        assert_eq!(PropValue::Null.as_text(), None);
    }

    #[test]
    fn heights() {
        assert_eq!(PropValue::Num(-9999.0).as_height_m(), None);
        assert_eq!(PropValue::Str("12.5".into()).as_height_m(), Some(12.5));
        assert_eq!(PropValue::Num(f64::NAN).as_height_m(), None);
    }

    #[test]
    fn first_matching_column_wins() {
        let props = feature_props::<()>(2, |name| {
            Ok(match name {
                "gml:id" => Some(vec![PropValue::Str("a".into()), PropValue::Null]),
                "lod" => Some(vec![PropValue::Num(1.0), PropValue::Num(2.0)]),
                "height" => Some(vec![PropValue::Num(3.5)]),
                _ => None,
            })
        })
        .unwrap();
        assert_eq!(
            props[0],
            FeatureProps { id: Some("a".into()), lod: Some("1".into()), measured_height_m: Some(3.5) }
        );
        assert_eq!(props[1], FeatureProps { id: None, lod: Some("2".into()), measured_height_m: None });
    }
}
