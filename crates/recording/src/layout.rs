//! Columns: which channels a recording has ([`Layout`]) and what each header column holds.

use std::collections::HashSet;

use crate::error::{ReadErrorKind, excerpt};

/// Names of the magnetic field columns (required), in order x, y, z.
pub(crate) const MAG: [&str; 3] = ["mx", "my", "mz"];
/// Names of the quaternion columns, scalar first.
pub(crate) const QUAT: [&str; 4] = ["qw", "qx", "qy", "qz"];
/// Names of the expected-field columns.
pub(crate) const REF: [&str; 3] = ["rx", "ry", "rz"];
/// Names of the gyro columns.
pub(crate) const GYRO: [&str; 3] = ["gx", "gy", "gz"];
/// Prefix of current channels.
pub(crate) const CURRENT_PREFIX: &str = "i_";

/// Which channels a recording has. `mx,my,mz` are always there; everything else is optional.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Layout {
    /// Has a `t` column (time, s).
    pub t: bool,
    /// Has a `temp` column (°C).
    pub temp: bool,
    /// Has `qw,qx,qy,qz` (attitude quaternion, sensor to NED).
    pub quat: bool,
    /// Has `rx,ry,rz` (expected field in sensor axes, µT).
    pub reference: bool,
    /// Has `gx,gy,gz` (angular rate, rad/s).
    pub gyro: bool,
    /// Current channels, full column names (`i_<name>`), in column order.
    pub currents: Vec<String>,
    /// Unknown columns carried along as text, in column order.
    pub extra: Vec<String>,
}

/// What one column of a file holds; indices are into the group, [`Layout::currents`] or [`Layout::extra`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    Time,
    Mag(usize),
    Temp,
    Quat(usize),
    Ref(usize),
    Gyro(usize),
    Current(usize),
    Extra(usize),
}

/// What a column name means, before indices of currents and extras are assigned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NameKind {
    Known(Role),
    Current,
    Extra,
}

/// What a column name means. Known names are matched whatever their case (`MX` is `mx`).
fn classify(name: &str) -> NameKind {
    let position = |group: &[&str]| group.iter().position(|g| g.eq_ignore_ascii_case(name));
    let prefix = CURRENT_PREFIX.len();
    if name.eq_ignore_ascii_case("t") {
        NameKind::Known(Role::Time)
    } else if name.eq_ignore_ascii_case("temp") {
        NameKind::Known(Role::Temp)
    } else if let Some(k) = position(&MAG) {
        NameKind::Known(Role::Mag(k))
    } else if let Some(k) = position(&QUAT) {
        NameKind::Known(Role::Quat(k))
    } else if let Some(k) = position(&REF) {
        NameKind::Known(Role::Ref(k))
    } else if let Some(k) = position(&GYRO) {
        NameKind::Known(Role::Gyro(k))
    } else if name.len() > prefix
        && name.as_bytes()[..prefix].eq_ignore_ascii_case(CURRENT_PREFIX.as_bytes())
    {
        NameKind::Current
    } else {
        NameKind::Extra
    }
}

/// The canonical name of a known role's column, for finding repeats whatever the case.
fn canonical(role: Role) -> Option<&'static str> {
    match role {
        Role::Time => Some("t"),
        Role::Temp => Some("temp"),
        Role::Mag(k) => Some(MAG[k]),
        Role::Quat(k) => Some(QUAT[k]),
        Role::Ref(k) => Some(REF[k]),
        Role::Gyro(k) => Some(GYRO[k]),
        Role::Current(_) | Role::Extra(_) => None,
    }
}

/// The header row of a file, understood: one role per column.
#[derive(Debug)]
pub(crate) struct Header {
    /// The role of each column, in file order.
    pub roles: Vec<Role>,
    /// The channels found.
    pub layout: Layout,
    /// Empty names after the last column (a spreadsheet pads rows with commas): rows may have as many empty fields
    /// after their last one.
    pub padding: usize,
}

/// A header problem and the 0-based column it is in, if any.
pub(crate) type ColumnProblem = (Option<usize>, ReadErrorKind);

impl Header {
    /// Understands a header row (names already trimmed). Errors name the 0-based column where one applies.
    pub(crate) fn parse(names: &[String]) -> Result<Header, ColumnProblem> {
        let mut padding = names.iter().rev().take_while(|n| n.is_empty()).count();
        if padding == names.len() {
            padding = 0;
        }
        let names = &names[..names.len() - padding];
        if names.iter().all(|n| n.parse::<f64>().is_ok()) {
            return Err((None, ReadErrorKind::MissingHeader { data_first: true }));
        }
        let mut seen = HashSet::with_capacity(names.len());
        let mut kinds = Vec::with_capacity(names.len());
        for (i, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err((Some(i), ReadErrorKind::EmptyColumnName));
            }
            let kind = classify(name);
            let key = match kind {
                NameKind::Known(role) => canonical(role).unwrap_or(name),
                NameKind::Current | NameKind::Extra => name,
            };
            if !seen.insert(key) {
                return Err((Some(i), ReadErrorKind::DuplicateColumn(excerpt(name))));
            }
            kinds.push(kind);
        }
        if let Some(missing) = MAG.iter().find(|m| !seen.contains(**m)) {
            return Err((None, ReadErrorKind::MissingColumn(missing)));
        }
        for group in [&QUAT[..], &REF, &GYRO] {
            let (present, missing): (Vec<&str>, Vec<&str>) =
                group.iter().partition(|g| seen.contains(**g));
            if !present.is_empty() && !missing.is_empty() {
                let (present, missing) = (present.join(","), missing.join(","));
                return Err((None, ReadErrorKind::IncompleteGroup { present, missing }));
            }
        }
        let mut layout = Layout::default();
        let roles = names
            .iter()
            .zip(kinds)
            .map(|(name, kind)| match kind {
                NameKind::Known(role) => {
                    match role {
                        Role::Time => layout.t = true,
                        Role::Temp => layout.temp = true,
                        Role::Quat(_) => layout.quat = true,
                        Role::Ref(_) => layout.reference = true,
                        Role::Gyro(_) => layout.gyro = true,
                        Role::Mag(_) | Role::Current(_) | Role::Extra(_) => {}
                    }
                    role
                }
                NameKind::Current => {
                    layout.currents.push(name.clone());
                    Role::Current(layout.currents.len() - 1)
                }
                NameKind::Extra => {
                    layout.extra.push(name.clone());
                    Role::Extra(layout.extra.len() - 1)
                }
            })
            .collect();
        Ok(Header {
            roles,
            layout,
            padding,
        })
    }
}

/// Which optional fixed channels a layout has.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Flags {
    pub t: bool,
    pub temp: bool,
    pub quat: bool,
    pub reference: bool,
    pub gyro: bool,
}

impl Layout {
    /// The optional fixed channels.
    pub(crate) fn flags(&self) -> Flags {
        Flags {
            t: self.t,
            temp: self.temp,
            quat: self.quat,
            reference: self.reference,
            gyro: self.gyro,
        }
    }

    /// The column names written for this layout: `t`, `mx,my,mz`, `temp`, `qw..qz`, `rx..rz`, `gx..gz`, then the
    /// currents and the extra columns, each in their own order.
    pub fn column_names(&self) -> Vec<&str> {
        let mut out = Vec::new();
        if self.t {
            out.push("t");
        }
        out.extend(MAG);
        if self.temp {
            out.push("temp");
        }
        if self.quat {
            out.extend(QUAT);
        }
        if self.reference {
            out.extend(REF);
        }
        if self.gyro {
            out.extend(GYRO);
        }
        out.extend(self.currents.iter().map(String::as_str));
        out.extend(self.extra.iter().map(String::as_str));
        out
    }

    /// Checks that the layout reads back as itself: current names are `i_<name>`, extra names are not names of
    /// known columns or currents, no name is empty, repeats or has surrounding blanks.
    pub(crate) fn check(&self) -> Result<(), String> {
        let names = self.column_names();
        if names.len() > crate::limits::MAX_COLUMNS {
            return Err(format!(
                "{} columns; a recording has at most {}",
                names.len(),
                crate::limits::MAX_COLUMNS
            ));
        }
        let mut seen = HashSet::with_capacity(names.len());
        for name in &names {
            if name.is_empty() || name.trim_ascii() != *name {
                return Err(format!("column name {name:?} cannot be written"));
            }
            if !seen.insert(*name) {
                return Err(format!("column name {name:?} repeated"));
            }
        }
        if let Some(bad) = self
            .currents
            .iter()
            .find(|c| classify(c) != NameKind::Current)
        {
            return Err(format!("current channel {bad:?} must be named i_<name>"));
        }
        if let Some(bad) = self.extra.iter().find(|c| classify(c) != NameKind::Extra) {
            return Err(format!(
                "extra column {bad:?} would be read back as a known column or a current"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(s: &str) -> Vec<String> {
        s.split(',').map(str::to_owned).collect()
    }

    #[test]
    fn header_roles_and_layout() {
        let h = Header::parse(&names("mz,note,t,qx,qw,qz,qy,i_motor,my,i_,mx,i_coil")).unwrap();
        assert_eq!(h.roles[0], Role::Mag(2));
        assert_eq!(h.roles[1], Role::Extra(0));
        assert_eq!(h.roles[3], Role::Quat(1));
        assert_eq!(h.roles[9], Role::Extra(1));
        assert_eq!(h.roles[11], Role::Current(1));
        assert!(h.layout.t && h.layout.quat && !h.layout.temp && !h.layout.gyro);
        assert_eq!(h.layout.currents, ["i_motor", "i_coil"]);
        assert_eq!(h.layout.extra, ["note", "i_"]);
        assert_eq!(h.padding, 0);
    }

    #[test]
    fn known_names_in_any_case_and_spreadsheet_padding() {
        let h = Header::parse(&names("T,MX,My,mZ,TEMP,I_Coil,Note,,,")).unwrap();
        assert_eq!(
            h.roles[..4],
            [Role::Time, Role::Mag(0), Role::Mag(1), Role::Mag(2)]
        );
        assert!(h.layout.t && h.layout.temp);
        assert_eq!(h.layout.currents, ["I_Coil"]);
        assert_eq!(h.layout.extra, ["Note"]);
        assert_eq!((h.roles.len(), h.padding), (7, 3));
        let (column, kind) = Header::parse(&names("mx,my,mz,MX")).unwrap_err();
        assert_eq!(column, Some(3));
        assert!(matches!(kind, ReadErrorKind::DuplicateColumn(n) if n == "MX"));
        assert!(matches!(
            Header::parse(&names("mx,,mz,my")),
            Err((Some(1), ReadErrorKind::EmptyColumnName))
        ));
    }

    #[test]
    fn layout_check() {
        let mut l = Layout {
            t: true,
            currents: vec!["i_a".into()],
            extra: vec!["note".into()],
            ..Layout::default()
        };
        assert_eq!(l.column_names(), ["t", "mx", "my", "mz", "i_a", "note"]);
        assert!(l.check().is_ok());
        l.extra.push("gx".into());
        assert!(l.check().is_err());
        l.extra = vec!["i_b".into()];
        assert!(l.check().is_err());
        l.extra = vec![" a".into()];
        assert!(l.check().is_err());
        l.extra = vec!["a,b".into()];
        assert!(l.check().is_ok(), "written quoted");
        l.extra = vec!["i_a".into()];
        assert!(l.check().is_err());
        l.extra.clear();
        l.currents = vec!["motor".into()];
        assert!(l.check().is_err());
    }
}
