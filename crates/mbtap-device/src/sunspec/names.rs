//! Names of SunSpec points on the command line: `MODEL.POINT`, the model by its group name
//! (`common.Mn`, `inverter_three_phase.W`) or ID (`103.W`), a repeated model's instance from 1
//! (`inverter_three_phase[2].W`), a repeating group's point (`mppt.module[1].DCA`); `MODEL`
//! alone for all its points (a model not known: its raw registers).

/// A point (or a whole model) asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointRef {
    /// The model's group name (lower case) or ID, as given.
    pub model: ModelSel,
    /// Which instance of the model, from 1.
    pub instance: usize,
    /// The point inside it (`W`, `module[1].DCA`); `None`: every point.
    pub point: Option<String>,
}

/// A model by name or ID.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModelSel {
    Id(u16),
    Name(String),
}

impl PointRef {
    /// Whether model `id` is the one asked for.
    #[must_use]
    pub fn is_model(&self, id: u16) -> bool {
        match &self.model {
            ModelSel::Id(i) => *i == id,
            ModelSel::Name(n) => super::model(id).is_some_and(|m| m.name.eq_ignore_ascii_case(n)),
        }
    }
}

/// Parses a point name.
///
/// # Errors
/// What is wrong, for the user.
pub fn parse_point_ref(s: &str) -> Result<PointRef, String> {
    let t = s.trim();
    let (model, point) = match t.split_once('.') {
        Some((m, p)) => (m, Some(p.to_owned())),
        None => (t, None),
    };
    if point.as_deref().is_some_and(str::is_empty) || model.is_empty() {
        return Err(format!("{s:?}: expected MODEL.POINT (common.Mn, inverter_three_phase.W, 103.W)"));
    }
    let (name, instance) = match model.split_once('[') {
        Some((n, rest)) => {
            let k = rest
                .strip_suffix(']')
                .and_then(|k| k.parse::<usize>().ok())
                .filter(|&k| k >= 1)
                .ok_or_else(|| format!("{s:?}: an instance is [1], [2], …"))?;
            (n, k)
        }
        None => (model, 1),
    };
    let sel = if let Ok(id) = name.parse::<u16>() {
        ModelSel::Id(id)
    } else {
        if super::model_named(name).is_none() {
            return Err(format!(
                "{s:?}: no SunSpec model is named {name:?} (a model's group name like common or inverter_three_phase, or its ID)"
            ));
        }
        ModelSel::Name(name.to_lowercase())
    };
    Ok(PointRef { model: sel, instance, point })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_ids_instances_and_groups() {
        assert_eq!(
            parse_point_ref("common.Mn"),
            Ok(PointRef { model: ModelSel::Name("common".into()), instance: 1, point: Some("Mn".into()) })
        );
        assert_eq!(parse_point_ref("103.W").map(|r| r.model), Ok(ModelSel::Id(103)));
        let r = parse_point_ref("inverter_three_phase[2].W").unwrap();
        assert_eq!((r.instance, r.is_model(103), r.is_model(101)), (2, true, false));
        assert_eq!(parse_point_ref("mppt.module[1].DCA").unwrap().point.as_deref(), Some("module[1].DCA"));
        assert_eq!(parse_point_ref("64999").unwrap().point, None);
        assert!(parse_point_ref("inverter.W").unwrap_err().contains("no SunSpec model"));
        assert!(parse_point_ref("common[0].Mn").is_err());
        assert!(parse_point_ref("common.").is_err());
    }
}
