//! A recording in memory: one vector per channel ([`Recording`]), and borrowed rows of it ([`Row`]).

use crate::error::HeaderError;
use crate::layout::{Flags, Layout};
use crate::metadata::Metadata;
use crate::sample::{Core, Sample, SampleError, check_row};

/// A whole recording in memory, column by column. Every column has [`Recording::len`] values.
///
/// Invariants established by the reader and by [`Recording::push`]: `mag_ut` and `t_s` are finite, `t_s` never
/// decreases, a present quaternion has unit length, a group with a missing component is NaN as a whole, and no
/// value is infinite.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The metadata block.
    pub meta: Metadata,
    /// Time, s; `None` when there is no `t` column.
    pub t_s: Option<Vec<f64>>,
    /// Magnetic field in sensor axes (`mx,my,mz`), µT.
    pub mag_ut: Vec<[f64; 3]>,
    /// Temperature, °C; NaN where missing.
    pub temp_c: Option<Vec<f64>>,
    /// Attitude `[w, x, y, z]`, normalised, rotating sensor-frame vectors into NED; NaN where missing.
    pub quat: Option<Vec<[f64; 4]>>,
    /// Expected field in sensor axes (`rx,ry,rz`), µT; NaN where missing.
    pub ref_ut: Option<Vec<[f64; 3]>>,
    /// Angular rate in sensor axes (`gx,gy,gz`), rad/s; NaN where missing.
    pub gyro_rad_s: Option<Vec<[f64; 3]>>,
    /// One channel per `i_<name>` column, in header order.
    pub currents: Vec<Channel>,
    /// Unknown columns, carried along as text.
    pub extra: Vec<TextColumn>,
}

/// A current channel (`i_<name>` column), A.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Full column name, e.g. `i_motor`.
    pub name: String,
    /// One value per row, A; NaN where missing.
    pub values: Vec<f64>,
}

/// An unknown column, kept as text so that it is written back unchanged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TextColumn {
    /// Column name.
    pub name: String,
    /// One value per row, as in the file (without CSV quoting).
    pub values: Vec<String>,
}

/// How many rows miss each optional group or channel; `None` where the recording has no such column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MissingCounts {
    /// Number of rows.
    pub rows: usize,
    /// Rows without `temp`.
    pub temp: Option<usize>,
    /// Rows without a quaternion.
    pub quat: Option<usize>,
    /// Rows without `rx,ry,rz`.
    pub reference: Option<usize>,
    /// Rows without `gx,gy,gz`.
    pub gyro: Option<usize>,
    /// Rows without a value, per current channel, in header order.
    pub currents: Vec<(String, usize)>,
}

/// A borrowed view of one row of a [`Recording`]. NaN marks an absent value (no such column, or missing here).
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    /// Time, s.
    pub t_s: f64,
    /// Magnetic field in sensor axes, µT.
    pub mag_ut: [f64; 3],
    /// Temperature, °C.
    pub temp_c: f64,
    /// Attitude quaternion `[w, x, y, z]`, sensor to NED.
    pub quat: [f64; 4],
    /// Expected field in sensor axes, µT.
    pub ref_ut: [f64; 3],
    /// Angular rate in sensor axes, rad/s.
    pub gyro_rad_s: [f64; 3],
    recording: &'a Recording,
    index: usize,
}

impl<'a> Row<'a> {
    /// The row's index in the recording.
    pub fn index(&self) -> usize {
        self.index
    }

    /// The row's currents, one per channel in [`Recording::currents`] order, A.
    pub fn currents_a(&self) -> impl ExactSizeIterator<Item = f64> + 'a {
        let i = self.index;
        self.recording
            .currents
            .iter()
            .map(move |c| c.values.get(i).copied().unwrap_or(f64::NAN))
    }

    /// The row's extra text values, one per column in [`Recording::extra`] order.
    pub fn extra(&self) -> impl ExactSizeIterator<Item = &'a str> + 'a {
        let i = self.index;
        self.recording
            .extra
            .iter()
            .map(move |c| c.values.get(i).map_or("", String::as_str))
    }

    /// The row as an owned [`Sample`].
    pub fn to_sample(&self) -> Sample {
        Sample {
            t_s: self.t_s,
            mag_ut: self.mag_ut,
            temp_c: self.temp_c,
            quat: self.quat,
            ref_ut: self.ref_ut,
            gyro_rad_s: self.gyro_rad_s,
            currents_a: self.currents_a().collect(),
            extra: self.extra().map(str::to_owned).collect(),
        }
    }

    pub(crate) fn core(&self) -> Core {
        Core {
            t_s: self.t_s,
            mag_ut: self.mag_ut,
            temp_c: self.temp_c,
            quat: self.quat,
            ref_ut: self.ref_ut,
            gyro_rad_s: self.gyro_rad_s,
        }
    }
}

/// Value `i` of an optional column, NaN when the column is absent (or too short).
fn at<T: Copy>(column: &Option<Vec<T>>, i: usize, nan: T) -> T {
    column
        .as_ref()
        .and_then(|c| c.get(i).copied())
        .unwrap_or(nan)
}

impl Recording {
    /// An empty recording with these metadata and channels, to be filled with [`Recording::push`].
    /// Fails if the metadata or the layout could not be written so that they read back as themselves.
    pub fn new(meta: Metadata, layout: &Layout) -> Result<Recording, HeaderError> {
        meta.check().map_err(HeaderError)?;
        layout.check().map_err(HeaderError)?;
        Ok(Recording::empty(meta, layout))
    }

    /// An empty recording, without checks.
    pub(crate) fn empty(meta: Metadata, layout: &Layout) -> Recording {
        Recording {
            meta,
            t_s: layout.t.then(Vec::new),
            mag_ut: Vec::new(),
            temp_c: layout.temp.then(Vec::new),
            quat: layout.quat.then(Vec::new),
            ref_ut: layout.reference.then(Vec::new),
            gyro_rad_s: layout.gyro.then(Vec::new),
            currents: layout
                .currents
                .iter()
                .map(|name| Channel {
                    name: name.clone(),
                    values: Vec::new(),
                })
                .collect(),
            extra: layout
                .extra
                .iter()
                .map(|name| TextColumn {
                    name: name.clone(),
                    values: Vec::new(),
                })
                .collect(),
        }
    }

    /// Appends a sample after checking it as the reader would check a row (see [`SampleError`]). The quaternion is
    /// stored normalised; values of channels the recording does not have are ignored.
    pub fn push(&mut self, s: &Sample) -> Result<(), SampleError> {
        let previous_t_s = self.t_s.as_ref().and_then(|t| t.last().copied());
        let names = self.currents.iter().map(|c| c.name.as_str());
        let core = check_row(
            self.flags(),
            previous_t_s,
            &s.core(),
            s.currents_a.iter().copied(),
            names,
            s.extra.len(),
            self.extra.len(),
        )?;
        self.mag_ut.push(core.mag_ut);
        let columns = [(&mut self.t_s, core.t_s), (&mut self.temp_c, core.temp_c)];
        for (column, value) in columns {
            if let Some(c) = column {
                c.push(value);
            }
        }
        if let Some(q) = &mut self.quat {
            q.push(core.quat);
        }
        for (column, value) in [
            (&mut self.ref_ut, core.ref_ut),
            (&mut self.gyro_rad_s, core.gyro_rad_s),
        ] {
            if let Some(c) = column {
                c.push(value);
            }
        }
        for (channel, value) in self.currents.iter_mut().zip(&s.currents_a) {
            channel.values.push(*value);
        }
        for (column, value) in self.extra.iter_mut().zip(&s.extra) {
            column.values.push(value.clone());
        }
        Ok(())
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.mag_ut.len()
    }

    /// True if the recording has no rows.
    pub fn is_empty(&self) -> bool {
        self.mag_ut.is_empty()
    }

    /// Keeps the rows where `keep` holds (one flag per row), in order, in every column.
    pub fn retain_rows(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "one flag per row");
        fn retain<T>(v: &mut Vec<T>, keep: &[bool]) {
            let mut k = keep.iter();
            v.retain(|_| *k.next().expect("one flag per row"));
        }
        fn retain_some<T>(v: &mut Option<Vec<T>>, keep: &[bool]) {
            if let Some(v) = v {
                retain(v, keep);
            }
        }
        retain(&mut self.mag_ut, keep);
        retain_some(&mut self.t_s, keep);
        retain_some(&mut self.temp_c, keep);
        retain_some(&mut self.quat, keep);
        retain_some(&mut self.ref_ut, keep);
        retain_some(&mut self.gyro_rad_s, keep);
        self.currents
            .iter_mut()
            .for_each(|c| retain(&mut c.values, keep));
        self.extra
            .iter_mut()
            .for_each(|c| retain(&mut c.values, keep));
    }

    /// Which channels the recording has.
    pub fn layout(&self) -> Layout {
        Layout {
            t: self.t_s.is_some(),
            temp: self.temp_c.is_some(),
            quat: self.quat.is_some(),
            reference: self.ref_ut.is_some(),
            gyro: self.gyro_rad_s.is_some(),
            currents: self.currents.iter().map(|c| c.name.clone()).collect(),
            extra: self.extra.iter().map(|c| c.name.clone()).collect(),
        }
    }

    pub(crate) fn flags(&self) -> Flags {
        Flags {
            t: self.t_s.is_some(),
            temp: self.temp_c.is_some(),
            quat: self.quat.is_some(),
            reference: self.ref_ut.is_some(),
            gyro: self.gyro_rad_s.is_some(),
        }
    }

    /// Row `i`. Panics if `i >= self.len()`.
    pub fn row(&self, i: usize) -> Row<'_> {
        Row {
            t_s: at(&self.t_s, i, f64::NAN),
            mag_ut: self.mag_ut[i],
            temp_c: at(&self.temp_c, i, f64::NAN),
            quat: at(&self.quat, i, [f64::NAN; 4]),
            ref_ut: at(&self.ref_ut, i, [f64::NAN; 3]),
            gyro_rad_s: at(&self.gyro_rad_s, i, [f64::NAN; 3]),
            recording: self,
            index: i,
        }
    }

    /// All rows, in order.
    pub fn rows(&self) -> impl ExactSizeIterator<Item = Row<'_>> {
        (0..self.len()).map(|i| self.row(i))
    }

    /// How many rows miss each optional group or channel.
    pub fn missing_counts(&self) -> MissingCounts {
        fn count<T>(column: &Option<Vec<T>>, missing: impl Fn(&T) -> bool) -> Option<usize> {
            column
                .as_ref()
                .map(|c| c.iter().filter(|v| missing(v)).count())
        }
        MissingCounts {
            rows: self.len(),
            temp: count(&self.temp_c, |v| v.is_nan()),
            quat: count(&self.quat, |q| q.iter().any(|v| v.is_nan())),
            reference: count(&self.ref_ut, |r| r.iter().any(|v| v.is_nan())),
            gyro: count(&self.gyro_rad_s, |g| g.iter().any(|v| v.is_nan())),
            currents: self
                .currents
                .iter()
                .map(|c| {
                    (
                        c.name.clone(),
                        c.values.iter().filter(|v| v.is_nan()).count(),
                    )
                })
                .collect(),
        }
    }

    /// Checks that every column has one value per row.
    pub(crate) fn check_lengths(&self) -> Result<(), String> {
        let rows = self.len();
        let lengths = [
            ("t", self.t_s.as_ref().map(Vec::len)),
            ("temp", self.temp_c.as_ref().map(Vec::len)),
            ("quat", self.quat.as_ref().map(Vec::len)),
            ("ref_ut", self.ref_ut.as_ref().map(Vec::len)),
            ("gyro_rad_s", self.gyro_rad_s.as_ref().map(Vec::len)),
        ];
        let named = lengths
            .into_iter()
            .chain(
                self.currents
                    .iter()
                    .map(|c| (c.name.as_str(), Some(c.values.len()))),
            )
            .chain(
                self.extra
                    .iter()
                    .map(|c| (c.name.as_str(), Some(c.values.len()))),
            );
        for (name, len) in named {
            if let Some(len) = len
                && len != rows
            {
                return Err(format!("column {name} has {len} values for {rows} rows"));
            }
        }
        Ok(())
    }
}
