//! Decoding any CDR message from its definition, into a generic [`Value`] tree.
//!
//! The typed decoders ([`super::messages`]) are what the pipelines use; this one serves
//! messages olmap has no type for (`olmap bag info`'s frame scan, tests against an
//! independent decoder, users' own topics).

use super::cdr::{CdrError, CdrReader};
use super::schema::{builtin_fields, Arity, Field, FieldType, MessageDefs, Primitive};

/// A decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// Signed integers.
    Int(i64),
    /// Unsigned integers.
    UInt(u64),
    /// Floating point (`float32` widened exactly).
    Float(f64),
    /// `string`.
    String(String),
    /// Arrays and sequences of `uint8`/`byte` (kept as bytes).
    Bytes(Vec<u8>),
    /// Other fixed arrays and sequences.
    Array(Vec<Value>),
    /// A message: its fields in order.
    Struct(Vec<(String, Value)>),
}

impl Value {
    /// A field of a struct value.
    pub fn field(&self, name: &str) -> Option<&Value> {
        match self {
            Value::Struct(fields) => fields.iter().find(|(n, _)| n == name).map(|(_, v)| v),
            _ => None,
        }
    }

    /// The value as JSON (non-finite floats become the strings `"nan"`, `"inf"`, `"-inf"`).
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::Value as J;
        match self {
            Value::Bool(b) => J::Bool(*b),
            Value::Int(i) => J::from(*i),
            Value::UInt(u) => J::from(*u),
            Value::Float(f) if f.is_finite() => J::from(*f),
            Value::Float(f) => J::String(
                if f.is_nan() {
                    "nan"
                } else if *f > 0.0 {
                    "inf"
                } else {
                    "-inf"
                }
                .into(),
            ),
            Value::String(s) => J::String(s.clone()),
            Value::Bytes(b) => J::Array(b.iter().map(|&x| J::from(x)).collect()),
            Value::Array(a) => J::Array(a.iter().map(Value::to_json).collect()),
            Value::Struct(fields) => J::Object(
                fields
                    .iter()
                    .map(|(n, v)| (n.clone(), v.to_json()))
                    .collect(),
            ),
        }
    }
}

/// Why a message could not be decoded from its definition.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The bytes do not hold what the definition says.
    #[error("field '{field}': {source}")]
    Cdr {
        /// Dotted path of the field being read.
        field: String,
        /// The CDR failure.
        source: CdrError,
    },
    /// The definition uses something this decoder does not read.
    #[error("field '{field}': {what}")]
    Unsupported {
        /// Dotted path of the field.
        field: String,
        /// What is not supported.
        what: String,
    },
}

/// How deep messages may nest (a guard against self-referencing schemas).
const MAX_DEPTH: usize = 32;

/// Decodes a whole CDR message of the schema's root type.
pub fn decode(defs: &MessageDefs, message: &[u8]) -> Result<Value, DecodeError> {
    let mut r = CdrReader::new(message).map_err(|source| DecodeError::Cdr {
        field: String::new(),
        source,
    })?;
    decode_struct(defs, &defs.root, &mut r, "", 0)
}

fn fields_of(defs: &MessageDefs, ty: &str) -> Option<Vec<Field>> {
    defs.types.get(ty).cloned().or_else(|| builtin_fields(ty))
}

fn decode_struct(
    defs: &MessageDefs,
    ty: &str,
    r: &mut CdrReader<'_>,
    path: &str,
    depth: usize,
) -> Result<Value, DecodeError> {
    if depth > MAX_DEPTH {
        return Err(DecodeError::Unsupported {
            field: path.into(),
            what: format!("messages nested more than {MAX_DEPTH} deep"),
        });
    }
    let fields = fields_of(defs, ty).ok_or_else(|| DecodeError::Unsupported {
        field: path.into(),
        what: format!("type {ty} is not defined"),
    })?;
    if fields.is_empty() {
        // An empty message is sent as one placeholder byte.
        let at = |source| DecodeError::Cdr {
            field: path.into(),
            source,
        };
        r.u8().map_err(at)?;
        return Ok(Value::Struct(Vec::new()));
    }
    let mut out = Vec::with_capacity(fields.len());
    for f in &fields {
        let fpath = if path.is_empty() {
            f.name.clone()
        } else {
            format!("{path}.{}", f.name)
        };
        let cdr = |source| DecodeError::Cdr {
            field: fpath.clone(),
            source,
        };
        let bytes = f.ty == FieldType::Primitive(Primitive::U8);
        let v = match f.arity {
            Arity::Single => decode_one(defs, &f.ty, r, &fpath, depth)?,
            Arity::Fixed(n) if bytes => {
                Value::Bytes(r.bytes(n, "uint8 array").map_err(cdr)?.to_vec())
            }
            Arity::Sequence { .. } if bytes => {
                Value::Bytes(r.byte_sequence().map_err(cdr)?.to_vec())
            }
            Arity::Fixed(n) => Value::Array(
                (0..n)
                    .map(|_| decode_one(defs, &f.ty, r, &fpath, depth))
                    .collect::<Result<_, _>>()?,
            ),
            Arity::Sequence { .. } => {
                let min = match &f.ty {
                    FieldType::Primitive(p) => p.min_size(),
                    FieldType::Message(_) => 1,
                };
                let n = r.count("sequence", min).map_err(cdr)?;
                Value::Array(
                    (0..n)
                        .map(|_| decode_one(defs, &f.ty, r, &fpath, depth))
                        .collect::<Result<_, _>>()?,
                )
            }
        };
        out.push((f.name.clone(), v));
    }
    Ok(Value::Struct(out))
}

fn decode_one(
    defs: &MessageDefs,
    ty: &FieldType,
    r: &mut CdrReader<'_>,
    path: &str,
    depth: usize,
) -> Result<Value, DecodeError> {
    let cdr = |source| DecodeError::Cdr {
        field: path.into(),
        source,
    };
    let p = match ty {
        FieldType::Message(t) => return decode_struct(defs, t, r, path, depth + 1),
        FieldType::Primitive(p) => *p,
    };
    Ok(match p {
        Primitive::Bool => Value::Bool(r.bool().map_err(cdr)?),
        Primitive::U8 => Value::UInt(r.u8().map_err(cdr)?.into()),
        Primitive::I8 => Value::Int(r.i8().map_err(cdr)?.into()),
        Primitive::I16 => Value::Int(r.i16().map_err(cdr)?.into()),
        Primitive::U16 => Value::UInt(r.u16().map_err(cdr)?.into()),
        Primitive::I32 => Value::Int(r.i32().map_err(cdr)?.into()),
        Primitive::U32 => Value::UInt(r.u32().map_err(cdr)?.into()),
        Primitive::I64 => Value::Int(r.i64().map_err(cdr)?),
        Primitive::U64 => Value::UInt(r.u64().map_err(cdr)?),
        Primitive::F32 => Value::Float(r.f32().map_err(cdr)?.into()),
        Primitive::F64 => Value::Float(r.f64().map_err(cdr)?),
        Primitive::String => Value::String(r.string().map_err(cdr)?.to_string()),
        Primitive::WString => {
            return Err(DecodeError::Unsupported {
                field: path.into(),
                what: "wstring fields are not decoded".into(),
            })
        }
    })
}
