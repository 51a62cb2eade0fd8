//! ROS 2 message definitions (`ros2msg`), as MCAP schema records carry them.
//!
//! A schema is the `.msg` text of the message, then the definitions of every type it uses,
//! each after a line of `=` and a line `MSG: package/Type`. Constants (`int32 X=1`) and
//! default values (`int32 x 5`) are read past; comments (`#`) are ignored. Type names are
//! normalised to `package/Type` (`sensor_msgs/msg/PointField` and `sensor_msgs/PointField`
//! are the same type; a bare `PointField` is looked up in the enclosing package).

use std::collections::BTreeMap;

/// A primitive ROS 2 field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    /// `bool`.
    Bool,
    /// `byte` / `char` / `uint8` (ROS 2 maps `char` to an unsigned byte).
    U8,
    /// `int8`.
    I8,
    /// `int16`.
    I16,
    /// `uint16`.
    U16,
    /// `int32`.
    I32,
    /// `uint32`.
    U32,
    /// `int64`.
    I64,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
    /// `string` (UTF-8, optionally bounded).
    String,
    /// `wstring`: recognised, not decoded.
    WString,
}

impl Primitive {
    fn parse(name: &str) -> Option<Primitive> {
        Some(match name {
            "bool" => Primitive::Bool,
            "byte" | "char" | "uint8" => Primitive::U8,
            "int8" => Primitive::I8,
            "int16" => Primitive::I16,
            "uint16" => Primitive::U16,
            "int32" => Primitive::I32,
            "uint32" => Primitive::U32,
            "int64" => Primitive::I64,
            "uint64" => Primitive::U64,
            "float32" => Primitive::F32,
            "float64" => Primitive::F64,
            "string" => Primitive::String,
            "wstring" => Primitive::WString,
            _ => return None,
        })
    }

    /// The smallest encoded size (bytes) of one value.
    pub fn min_size(self) -> usize {
        match self {
            Primitive::Bool | Primitive::U8 | Primitive::I8 => 1,
            Primitive::I16 | Primitive::U16 => 2,
            Primitive::I32 | Primitive::U32 | Primitive::F32 => 4,
            Primitive::String | Primitive::WString => 4,
            Primitive::I64 | Primitive::U64 | Primitive::F64 => 8,
        }
    }
}

/// The element type of a field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FieldType {
    /// A primitive.
    Primitive(Primitive),
    /// Another message, by normalised name (`package/Type`).
    Message(String),
}

/// How many values a field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// One value.
    Single,
    /// Exactly N values, no count on the wire.
    Fixed(usize),
    /// A sequence (count on the wire), optionally bounded.
    Sequence {
        /// The declared bound (`[<=N]`), if any.
        bound: Option<usize>,
    },
}

/// One field of a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// The field's name.
    pub name: String,
    /// Its element type.
    pub ty: FieldType,
    /// Single value, fixed array or sequence.
    pub arity: Arity,
}

/// The parsed definitions of one schema: the root type and every type it uses.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MessageDefs {
    /// The root type's normalised name.
    pub root: String,
    /// Fields of every type, by normalised name.
    pub types: BTreeMap<String, Vec<Field>>,
}

/// A schema that could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("message definition of {type_name}, line {line}: {reason}")]
pub struct SchemaError {
    /// The type being defined.
    pub type_name: String,
    /// Line within the schema text (1-based).
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

/// `sensor_msgs/msg/PointCloud2` → `sensor_msgs/PointCloud2`.
pub fn normalise_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, "msg", ty] => format!("{pkg}/{ty}"),
        _ => name.to_string(),
    }
}

fn package_of(name: &str) -> &str {
    name.split('/').next().unwrap_or("")
}

/// Parses a `ros2msg` schema whose root type is `root_name`.
pub fn parse_schema(root_name: &str, text: &str) -> Result<MessageDefs, SchemaError> {
    let root = normalise_type_name(root_name);
    let mut defs = MessageDefs {
        root: root.clone(),
        types: BTreeMap::new(),
    };
    let mut current = root;
    let mut fields = Vec::new();
    let mut expect_msg_line = false;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        let err = |reason: String| SchemaError {
            type_name: String::new(),
            line: line_no,
            reason,
        };
        if line.len() >= 3 && line.bytes().all(|b| b == b'=') {
            defs.types
                .insert(current.clone(), std::mem::take(&mut fields));
            expect_msg_line = true;
            continue;
        }
        if let Some(name) = line.strip_prefix("MSG:") {
            current = normalise_type_name(name.trim());
            if defs.types.contains_key(&current) {
                return Err(SchemaError {
                    type_name: current,
                    ..err("defined twice".into())
                });
            }
            expect_msg_line = false;
            continue;
        }
        let line = strip_comment(line);
        if line.is_empty() {
            continue;
        }
        if expect_msg_line {
            return Err(err(format!("expected 'MSG: package/Type', found '{line}'")));
        }
        let mut tokens = line.split_whitespace();
        let (Some(ty), Some(name)) = (tokens.next(), tokens.next()) else {
            return Err(SchemaError {
                type_name: current.clone(),
                ..err(format!("expected 'TYPE NAME', found '{line}'"))
            });
        };
        let next = tokens.next().unwrap_or("");
        if name.contains('=') || next.starts_with('=') {
            continue; // a constant: not on the wire
        }
        let field = parse_field(ty, name, package_of(&current)).map_err(|reason| SchemaError {
            type_name: current.clone(),
            ..err(reason)
        })?;
        fields.push(field);
    }
    defs.types.insert(current, fields);
    // Every referenced type must be defined (or be a known built-in).
    for (name, fields) in &defs.types {
        for f in fields {
            if let FieldType::Message(t) = &f.ty {
                if !defs.types.contains_key(t) && builtin_fields(t).is_none() {
                    return Err(SchemaError {
                        type_name: name.clone(),
                        line: 0,
                        reason: format!(
                            "field '{}' uses type {t}, which the schema does not define",
                            f.name
                        ),
                    });
                }
            }
        }
    }
    Ok(defs)
}

/// Fields of types ROS 1 style schemas name without defining (`time`, `duration`).
pub(crate) fn builtin_fields(name: &str) -> Option<Vec<Field>> {
    match name {
        "builtin_interfaces/Time" | "builtin_interfaces/Duration" => Some(vec![
            Field {
                name: "sec".into(),
                ty: FieldType::Primitive(Primitive::I32),
                arity: Arity::Single,
            },
            Field {
                name: "nanosec".into(),
                ty: FieldType::Primitive(Primitive::U32),
                arity: Arity::Single,
            },
        ]),
        _ => None,
    }
}

fn strip_comment(line: &str) -> &str {
    // A '#' starts a comment unless it sits inside a quoted default value.
    let mut quote: Option<char> = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '#') => return line[..i].trim(),
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            _ => {}
        }
    }
    line
}

fn parse_field(ty: &str, name: &str, package: &str) -> Result<Field, String> {
    let (base, arity) = match ty.find('[') {
        None => (ty, Arity::Single),
        Some(open) => {
            let inner = ty[open + 1..]
                .strip_suffix(']')
                .ok_or_else(|| format!("malformed array type '{ty}'"))?;
            let arity = if inner.is_empty() {
                Arity::Sequence { bound: None }
            } else if let Some(b) = inner.strip_prefix("<=") {
                Arity::Sequence {
                    bound: Some(
                        b.parse()
                            .map_err(|_| format!("bad array bound in '{ty}'"))?,
                    ),
                }
            } else {
                Arity::Fixed(
                    inner
                        .parse()
                        .map_err(|_| format!("bad array size in '{ty}'"))?,
                )
            };
            (&ty[..open], arity)
        }
    };
    // Bounded strings: `string<=10`.
    let base_name = base.split("<=").next().unwrap_or(base);
    let field_ty = match Primitive::parse(base_name) {
        Some(p) => FieldType::Primitive(p),
        None => FieldType::Message(match base_name {
            "time" => "builtin_interfaces/Time".into(),
            "duration" => "builtin_interfaces/Duration".into(),
            "Header" => "std_msgs/Header".into(),
            n if n.contains('/') => normalise_type_name(n),
            n => format!("{package}/{n}"),
        }),
    };
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("bad field name '{name}'"));
    }
    Ok(Field {
        name: name.to_string(),
        ty: field_ty,
        arity,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_types_constants_defaults_and_arrays_parse() {
        let text = "# comment\nstd_msgs/Header header\nPointField[] fields\nuint8 A=3\n\
                    float32[3] v [1.0, 2.0, 3.0]\nstring<=5[<=2] names\n\
                    ================================================================================\n\
                    MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
                    ================================================================================\n\
                    MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
                    ================================================================================\n\
                    MSG: sensor_msgs/PointField\nstring name # the name\nuint32 offset\n";
        let defs = parse_schema("sensor_msgs/msg/Foo", text).unwrap();
        assert_eq!(defs.root, "sensor_msgs/Foo");
        let root = &defs.types["sensor_msgs/Foo"];
        assert_eq!(root.len(), 4);
        assert_eq!(
            root[1].ty,
            FieldType::Message("sensor_msgs/PointField".into())
        );
        assert_eq!(root[1].arity, Arity::Sequence { bound: None });
        assert_eq!(root[2].arity, Arity::Fixed(3));
        assert_eq!(root[3].ty, FieldType::Primitive(Primitive::String));
        assert_eq!(root[3].arity, Arity::Sequence { bound: Some(2) });
        assert_eq!(defs.types["sensor_msgs/PointField"].len(), 2);
    }

    #[test]
    fn an_undefined_type_is_an_error() {
        let e = parse_schema("a/msg/B", "c/D d\n").unwrap_err();
        assert!(e.reason.contains("c/D"), "{e}");
    }
}
