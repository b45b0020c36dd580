//! A sweep's rows as `results.parquet`: one row per flight, in flight order. Columns:
//!
//! - `index`, `cell`, `replicate`, `seed` (INT64);
//! - one per axis, named by its key (`gains.k`; DOUBLE);
//! - `exit_code` (INT32), `error` (text, null when the flight flew), `wall_s` (DOUBLE);
//! - every field of the flight's `summary.json`, flattened ([`super::rows::flatten`]):
//!   whole numbers INT64, other numbers DOUBLE, yes/no BOOLEAN, text UTF-8; null where a
//!   flight has none. A summary field that has an axis's name is written as
//!   `summary.<name>`.
//!
//! Snappy-compressed, one row group per 100 000 flights.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use parquet::basic::{Compression, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int32Type, Int64Type};
use parquet::errors::ParquetError;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use super::rows::{Cell, FlightRow, flatten};

/// Flights per row group.
const ROW_GROUP: usize = 100_000;

/// What a summary column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Int,
    Float,
    Bool,
    Text,
}

impl Kind {
    fn of(cell: &Cell) -> Self {
        match cell {
            Cell::Int(_) => Self::Int,
            Cell::Float(_) => Self::Float,
            Cell::Bool(_) => Self::Bool,
            Cell::Text(_) => Self::Text,
        }
    }

    /// The kind that holds both: a whole number and a fraction are a DOUBLE; anything
    /// else mixed is text.
    fn join(self, other: Self) -> Self {
        match (self, other) {
            (a, b) if a == b => a,
            (Self::Int, Self::Float) | (Self::Float, Self::Int) => Self::Float,
            _ => Self::Text,
        }
    }
}

/// One column's values in one row group.
enum Values {
    Int64(Vec<i64>),
    Int32(Vec<i32>),
    Double(Vec<f64>),
    /// A summary column (or `error`): nulls where a flight has none.
    Optional(Kind, Vec<Option<Cell>>),
}

/// Writes `rows` (in order) to `path`, the axes' columns named by `axes`.
///
/// # Errors
/// The file cannot be written, or the Parquet writer refuses the schema.
pub fn write(path: &Path, axes: &[String], rows: &[FlightRow]) -> Result<(), ParquetError> {
    let flat: Vec<BTreeMap<String, Cell>> = rows.iter().map(|r| flatten(&r.summary)).collect();
    let mut kinds: BTreeMap<&str, Kind> = BTreeMap::new();
    for f in &flat {
        for (name, cell) in f {
            let k = Kind::of(cell);
            kinds
                .entry(name.as_str())
                .and_modify(|e| *e = e.join(k))
                .or_insert(k);
        }
    }
    let mut fields = vec![
        required("index", Physical::INT64)?,
        required("cell", Physical::INT64)?,
        required("replicate", Physical::INT64)?,
        required("seed", Physical::INT64)?,
    ];
    for a in axes {
        fields.push(required(a, Physical::DOUBLE)?);
    }
    fields.push(required("exit_code", Physical::INT32)?);
    fields.push(optional("error", Kind::Text)?);
    fields.push(required("wall_s", Physical::DOUBLE)?);
    let summary_name = |name: &str| {
        if axes.iter().any(|a| a == name)
            || [
                "index",
                "cell",
                "replicate",
                "seed",
                "exit_code",
                "error",
                "wall_s",
            ]
            .contains(&name)
        {
            format!("summary.{name}")
        } else {
            name.to_owned()
        }
    };
    for (name, kind) in &kinds {
        fields.push(optional(&summary_name(name), *kind)?);
    }
    let schema = Arc::new(
        Type::group_type_builder("flight")
            .with_fields(fields)
            .build()?,
    );
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .set_created_by(format!("ringswarm {}", env!("CARGO_PKG_VERSION")))
            .build(),
    );
    let file = std::fs::File::create(path)?;
    let mut writer = SerializedFileWriter::new(file, schema, props)?;
    for (group, flat) in rows.chunks(ROW_GROUP).zip(flat.chunks(ROW_GROUP)) {
        let mut rg = writer.next_row_group()?;
        let ints = |get: fn(&FlightRow) -> i64| Values::Int64(group.iter().map(get).collect());
        let mut columns = vec![
            ints(|r| r.index as i64),
            ints(|r| r.cell as i64),
            ints(|r| r.replicate as i64),
            ints(|r| r.seed as i64),
        ];
        for a in 0..axes.len() {
            columns.push(Values::Double(
                group
                    .iter()
                    .map(|r| r.values.get(a).copied().unwrap_or(f64::NAN))
                    .collect(),
            ));
        }
        columns.push(Values::Int32(
            group.iter().map(|r| i32::from(r.exit_code)).collect(),
        ));
        columns.push(Values::Optional(
            Kind::Text,
            group
                .iter()
                .map(|r| r.error.clone().map(Cell::Text))
                .collect(),
        ));
        columns.push(Values::Double(group.iter().map(|r| r.wall_s).collect()));
        for (name, kind) in &kinds {
            columns.push(Values::Optional(
                *kind,
                flat.iter().map(|f| f.get(*name).cloned()).collect(),
            ));
        }
        let mut next = columns.iter();
        while let Some(mut column) = rg.next_column()? {
            let Some(values) = next.next() else {
                return Err(ParquetError::General("more columns than values".to_owned()));
            };
            match values {
                Values::Int64(v) => {
                    column.typed::<Int64Type>().write_batch(v, None, None)?;
                }
                Values::Int32(v) => {
                    column.typed::<Int32Type>().write_batch(v, None, None)?;
                }
                Values::Double(v) => {
                    column.typed::<DoubleType>().write_batch(v, None, None)?;
                }
                Values::Optional(kind, cells) => write_optional(&mut column, *kind, cells)?,
            }
            column.close()?;
        }
        rg.close()?;
    }
    writer.close()?;
    Ok(())
}

fn required(name: &str, physical: Physical) -> Result<Arc<Type>, ParquetError> {
    Ok(Arc::new(
        Type::primitive_type_builder(name, physical)
            .with_repetition(Repetition::REQUIRED)
            .build()?,
    ))
}

fn optional(name: &str, kind: Kind) -> Result<Arc<Type>, ParquetError> {
    let b = match kind {
        Kind::Int => Type::primitive_type_builder(name, Physical::INT64),
        Kind::Float => Type::primitive_type_builder(name, Physical::DOUBLE),
        Kind::Bool => Type::primitive_type_builder(name, Physical::BOOLEAN),
        Kind::Text => Type::primitive_type_builder(name, Physical::BYTE_ARRAY)
            .with_logical_type(Some(LogicalType::String)),
    };
    Ok(Arc::new(b.with_repetition(Repetition::OPTIONAL).build()?))
}

/// An optional column's values of kind `kind` (a cell of another kind converted: a
/// whole number to a DOUBLE, anything to text), nulls as definition level 0.
fn write_optional(
    c: &mut parquet::file::writer::SerializedColumnWriter<'_>,
    kind: Kind,
    cells: &[Option<Cell>],
) -> Result<(), ParquetError> {
    let defs: Vec<i16> = cells.iter().map(|c| i16::from(c.is_some())).collect();
    let present = cells.iter().flatten();
    match kind {
        Kind::Int => {
            let v: Vec<i64> = present
                .map(|c| match c {
                    Cell::Int(i) => *i,
                    _ => 0,
                })
                .collect();
            c.typed::<Int64Type>().write_batch(&v, Some(&defs), None)?;
        }
        Kind::Float => {
            let v: Vec<f64> = present
                .map(|c| match c {
                    Cell::Float(x) => *x,
                    Cell::Int(i) => *i as f64,
                    _ => f64::NAN,
                })
                .collect();
            c.typed::<DoubleType>().write_batch(&v, Some(&defs), None)?;
        }
        Kind::Bool => {
            let v: Vec<bool> = present.map(|c| matches!(c, Cell::Bool(true))).collect();
            c.typed::<BoolType>().write_batch(&v, Some(&defs), None)?;
        }
        Kind::Text => {
            let v: Vec<ByteArray> = present
                .map(|c| {
                    let text = match c {
                        Cell::Text(s) => s.clone(),
                        Cell::Int(i) => i.to_string(),
                        Cell::Float(x) => x.to_string(),
                        Cell::Bool(b) => b.to_string(),
                    };
                    ByteArray::from(text.into_bytes())
                })
                .collect();
            c.typed::<ByteArrayType>()
                .write_batch(&v, Some(&defs), None)?;
        }
    }
    Ok(())
}
