//! LCM type definitions (`.lcm` files) and the fingerprint `lcm-gen` derives
//! from them.
//!
//! The `.lcm` files in `bus/lcmtypes/` are the source of truth: the build
//! script parses them with this module, computes every fingerprint with
//! [`fingerprints`] and generates the Rust codecs. The same code is public so
//! tests (and users with their own types) can check fingerprints against
//! `lcm-gen`. This file uses only `std`, because the build script includes it.
//!
//! The hash follows `lcmgen.c` (`hash_update`, `hash_string_update`,
//! `lcm_struct_hash`): an arithmetic right shift on `i64`, a wrapping add of
//! each byte as a *signed* char, member names, primitive type names, array
//! dimension modes and size texts exactly as written.

use std::collections::BTreeMap;
use std::fmt;

/// LCM's primitive types.
pub const PRIMITIVES: [&str; 9] = [
    "int8_t", "int16_t", "int32_t", "int64_t", "byte", "float", "double", "string", "boolean",
];

/// True for LCM's primitive type names.
pub fn is_primitive(type_name: &str) -> bool {
    PRIMITIVES.contains(&type_name)
}

/// True for the primitive types that may size an array.
pub fn is_integer(type_name: &str) -> bool {
    matches!(type_name, "int8_t" | "int16_t" | "int32_t" | "int64_t")
}

/// One `struct` of a `.lcm` file.
#[derive(Debug, Clone, PartialEq)]
pub struct StructDef {
    pub package: String,
    pub name: String,
    /// Comment lines written right above the struct.
    pub doc: String,
    pub constants: Vec<ConstDef>,
    pub members: Vec<Member>,
}

impl StructDef {
    /// `package.name`, or `name` without a package.
    pub fn full_name(&self) -> String {
        if self.package.is_empty() {
            self.name.clone()
        } else {
            format!("{}.{}", self.package, self.name)
        }
    }
}

/// `const int32_t MAX_WIDTH = 2048;`
#[derive(Debug, Clone, PartialEq)]
pub struct ConstDef {
    pub type_name: String,
    pub name: String,
    /// The value exactly as written.
    pub value: String,
}

/// A data member.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub name: String,
    /// Type as written: a primitive, `other_t` or `package.other_t`.
    pub type_name: String,
    /// Array dimensions, outermost first; empty for a scalar.
    pub dims: Vec<Dim>,
    /// Comments right above the member and after it on the same line.
    pub doc: String,
}

/// One array dimension.
#[derive(Debug, Clone, PartialEq)]
pub enum Dim {
    /// A constant size, with its text exactly as written.
    Const { size: usize, text: String },
    /// A size given by an earlier integer member.
    Var { member: String },
}

impl Dim {
    fn mode(&self) -> i8 {
        match self {
            Dim::Const { .. } => 0,
            Dim::Var { .. } => 1,
        }
    }

    fn text(&self) -> &str {
        match self {
            Dim::Const { text, .. } => text,
            Dim::Var { member } => member,
        }
    }
}

/// A `.lcm` file that does not parse or does not make sense.
#[derive(Debug, Clone, PartialEq)]
pub struct SchemaError {
    /// 1-based line, 0 when the problem spans files.
    pub line: usize,
    pub message: String,
}

impl fmt::Display for SchemaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            f.write_str(&self.message)
        }
    }
}

impl std::error::Error for SchemaError {}

#[derive(Debug, Clone, PartialEq)]
enum Token {
    Word(String),
    Punct(char),
    Comment(String),
}

#[derive(Debug, Clone)]
struct Spanned {
    token: Token,
    line: usize,
}

fn tokenize(source: &str) -> Result<Vec<Spanned>, SchemaError> {
    let mut tokens = Vec::new();
    let chars: Vec<char> = source.chars().collect();
    let (mut i, mut line) = (0, 1);
    while i < chars.len() {
        let c = chars[i];
        if c == '\n' {
            line += 1;
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            let start = i + 2;
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
            let text: String = chars[start..i].iter().collect();
            tokens.push(Spanned {
                token: Token::Comment(text.trim_start_matches('/').trim().to_owned()),
                line,
            });
        } else if c == '/' && chars.get(i + 1) == Some(&'*') {
            let start_line = line;
            let start = i + 2;
            i += 2;
            while i + 1 < chars.len() && !(chars[i] == '*' && chars[i + 1] == '/') {
                if chars[i] == '\n' {
                    line += 1;
                }
                i += 1;
            }
            if i + 1 >= chars.len() {
                return Err(SchemaError {
                    line: start_line,
                    message: "unterminated /* comment".into(),
                });
            }
            let text: String = chars[start..i].iter().collect();
            let text = text
                .lines()
                .map(|l| l.trim().trim_start_matches('*').trim())
                .filter(|l| !l.is_empty())
                .collect::<Vec<_>>()
                .join("\n");
            tokens.push(Spanned {
                token: Token::Comment(text),
                line: start_line,
            });
            i += 2;
        } else if c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '-' || c == '+' {
            let start = i;
            while i < chars.len()
                && (chars[i].is_ascii_alphanumeric() || matches!(chars[i], '_' | '.' | '-' | '+'))
            {
                i += 1;
            }
            tokens.push(Spanned {
                token: Token::Word(chars[start..i].iter().collect()),
                line,
            });
        } else if "{}[];,=".contains(c) {
            tokens.push(Spanned {
                token: Token::Punct(c),
                line,
            });
            i += 1;
        } else {
            return Err(SchemaError {
                line,
                message: format!("unexpected character {c:?}"),
            });
        }
    }
    Ok(tokens)
}

struct Parser {
    tokens: Vec<Spanned>,
    pos: usize,
    /// Comments seen since the last declaration.
    pending_doc: Vec<String>,
}

impl Parser {
    fn line(&self) -> usize {
        self.tokens
            .get(self.pos)
            .or_else(|| self.tokens.last())
            .map_or(0, |t| t.line)
    }

    fn error(&self, message: impl Into<String>) -> SchemaError {
        SchemaError {
            line: self.line(),
            message: message.into(),
        }
    }

    /// Next non-comment token; comments are collected as documentation.
    fn next(&mut self) -> Option<Token> {
        while let Some(spanned) = self.tokens.get(self.pos) {
            self.pos += 1;
            match &spanned.token {
                Token::Comment(text) => self.pending_doc.push(text.clone()),
                token => return Some(token.clone()),
            }
        }
        None
    }

    fn peek(&mut self) -> Option<Token> {
        let save = (self.pos, self.pending_doc.len());
        let token = self.next();
        self.pos = save.0;
        self.pending_doc.truncate(save.1);
        token
    }

    fn word(&mut self, what: &str) -> Result<String, SchemaError> {
        match self.next() {
            Some(Token::Word(w)) => Ok(w),
            other => Err(self.error(format!(
                "expected {what}, found {}",
                describe(other.as_ref())
            ))),
        }
    }

    fn punct(&mut self, c: char) -> Result<(), SchemaError> {
        match self.next() {
            Some(Token::Punct(p)) if p == c => Ok(()),
            other => Err(self.error(format!(
                "expected '{c}', found {}",
                describe(other.as_ref())
            ))),
        }
    }

    fn take_doc(&mut self) -> String {
        std::mem::take(&mut self.pending_doc).join("\n")
    }

    /// A comment on the same line as the token just consumed.
    fn trailing_comment(&mut self) -> Option<String> {
        let line = self.tokens.get(self.pos.checked_sub(1)?)?.line;
        match self.tokens.get(self.pos) {
            Some(Spanned {
                token: Token::Comment(text),
                line: l,
            }) if *l == line => {
                let text = text.clone();
                self.pos += 1;
                Some(text)
            }
            _ => None,
        }
    }
}

fn describe(token: Option<&Token>) -> String {
    match token {
        None => "end of file".into(),
        Some(Token::Word(w)) => format!("'{w}'"),
        Some(Token::Punct(c)) => format!("'{c}'"),
        Some(Token::Comment(_)) => "a comment".into(),
    }
}

fn is_identifier(word: &str) -> bool {
    let mut chars = word.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn is_type_name(word: &str) -> bool {
    word.split('.').all(is_identifier)
}

/// Parses one `.lcm` file into its structs.
pub fn parse(source: &str) -> Result<Vec<StructDef>, SchemaError> {
    let mut p = Parser {
        tokens: tokenize(source)?,
        pos: 0,
        pending_doc: Vec::new(),
    };
    let mut package = String::new();
    let mut structs = Vec::new();
    while let Some(token) = p.next() {
        match token {
            Token::Word(w) if w == "package" => {
                package = p.word("a package name")?;
                if !is_type_name(&package) {
                    return Err(p.error(format!("'{package}' is not a package name")));
                }
                p.punct(';')?;
                p.take_doc();
            }
            Token::Word(w) if w == "struct" => {
                let doc = p.take_doc();
                structs.push(parse_struct(&mut p, &package, doc)?);
            }
            other => {
                return Err(p.error(format!(
                    "expected 'package' or 'struct', found {}",
                    describe(Some(&other))
                )));
            }
        }
    }
    Ok(structs)
}

fn parse_struct(p: &mut Parser, package: &str, doc: String) -> Result<StructDef, SchemaError> {
    let name = p.word("a struct name")?;
    if !is_identifier(&name) {
        return Err(p.error(format!("'{name}' is not a struct name")));
    }
    p.punct('{')?;
    p.take_doc();
    let mut def = StructDef {
        package: package.to_owned(),
        name,
        doc,
        constants: Vec::new(),
        members: Vec::new(),
    };
    loop {
        match p.peek() {
            Some(Token::Punct('}')) => {
                p.next();
                p.take_doc();
                return Ok(def);
            }
            None => return Err(p.error(format!("struct {} is not closed with '}}'", def.name))),
            _ => {}
        }
        let first = p.word("a member type or 'const'")?;
        if first == "const" {
            let type_name = p.word("a constant type")?;
            if !is_primitive(&type_name) || type_name == "string" || type_name == "boolean" {
                return Err(p.error(format!("constant type '{type_name}' is not a number type")));
            }
            loop {
                let name = p.word("a constant name")?;
                p.punct('=')?;
                let value = p.word("a constant value")?;
                def.constants.push(ConstDef {
                    type_name: type_name.clone(),
                    name,
                    value,
                });
                match p.next() {
                    Some(Token::Punct(',')) => continue,
                    Some(Token::Punct(';')) => break,
                    other => {
                        return Err(p.error(format!(
                            "expected ',' or ';', found {}",
                            describe(other.as_ref())
                        )));
                    }
                }
            }
            p.trailing_comment();
            p.take_doc();
            continue;
        }
        let type_name = first;
        if !is_type_name(&type_name) {
            return Err(p.error(format!("'{type_name}' is not a type name")));
        }
        let doc_above = p.take_doc();
        loop {
            let name = p.word("a member name")?;
            if !is_identifier(&name) {
                return Err(p.error(format!("'{name}' is not a member name")));
            }
            let mut dims = Vec::new();
            while p.peek() == Some(Token::Punct('[')) {
                p.next();
                let size = p.word("an array size")?;
                p.punct(']')?;
                dims.push(match size.parse::<usize>() {
                    Ok(n) => Dim::Const {
                        size: n,
                        text: size,
                    },
                    Err(_) => {
                        let Some(sizer) = def.members.iter().find(|m| m.name == size) else {
                            return Err(p.error(format!(
                                "array size '{size}' of '{name}' is not an earlier member of {}",
                                def.name
                            )));
                        };
                        if !is_integer(&sizer.type_name) || !sizer.dims.is_empty() {
                            return Err(p.error(format!(
                                "array size '{size}' of '{name}' must be a scalar integer member"
                            )));
                        }
                        Dim::Var { member: size }
                    }
                });
            }
            if def.members.iter().any(|m| m.name == name) {
                return Err(p.error(format!("member '{name}' is declared twice in {}", def.name)));
            }
            let separator = p.next();
            let trailing = p.trailing_comment();
            let doc = [doc_above.clone(), trailing.unwrap_or_default()]
                .into_iter()
                .filter(|d| !d.is_empty())
                .collect::<Vec<_>>()
                .join("\n");
            def.members.push(Member {
                name,
                type_name: type_name.clone(),
                dims,
                doc,
            });
            match separator {
                Some(Token::Punct(',')) => continue,
                Some(Token::Punct(';')) => break,
                other => {
                    return Err(p.error(format!(
                        "expected ',' or ';' after a member, found {}",
                        describe(other.as_ref())
                    )));
                }
            }
        }
        p.take_doc();
    }
}

fn hash_update(v: i64, c: i8) -> i64 {
    ((v << 8) ^ (v >> 55)).wrapping_add(i64::from(c))
}

fn hash_string(v: i64, s: &str) -> i64 {
    // lcm-gen hashes the length and the bytes as C `char`s (signed).
    let mut v = hash_update(v, s.len() as i8);
    for b in s.bytes() {
        v = hash_update(v, b as i8);
    }
    v
}

/// The struct's own hash, before nested types are folded in.
pub fn base_hash(def: &StructDef) -> u64 {
    let mut v: i64 = 0x1234_5678;
    for member in &def.members {
        v = hash_string(v, &member.name);
        if is_primitive(&member.type_name) {
            v = hash_string(v, &member.type_name);
        }
        v = hash_update(v, member.dims.len() as i8);
        for dim in &member.dims {
            v = hash_update(v, dim.mode());
            v = hash_string(v, dim.text());
        }
    }
    v as u64
}

/// Resolves a member's type to the full name of a struct in `structs`.
pub fn resolve<'a>(
    structs: &'a BTreeMap<String, StructDef>,
    owner: &StructDef,
    type_name: &str,
) -> Option<&'a StructDef> {
    if type_name.contains('.') {
        structs.get(type_name)
    } else {
        let full = if owner.package.is_empty() {
            type_name.to_owned()
        } else {
            format!("{}.{type_name}", owner.package)
        };
        structs.get(&full)
    }
}

/// Fingerprints of every struct, keyed by full name, exactly as lcm-gen
/// computes them (nested types folded in, recursion cut at repeated types).
pub fn fingerprints(defs: &[StructDef]) -> Result<BTreeMap<String, u64>, SchemaError> {
    let mut structs = BTreeMap::new();
    for def in defs {
        if structs.insert(def.full_name(), def.clone()).is_some() {
            return Err(SchemaError {
                line: 0,
                message: format!("struct {} is defined twice", def.full_name()),
            });
        }
    }
    for def in defs {
        for member in &def.members {
            if !is_primitive(&member.type_name)
                && resolve(&structs, def, &member.type_name).is_none()
            {
                return Err(SchemaError {
                    line: 0,
                    message: format!(
                        "{}.{} has type {}, which no .lcm file defines",
                        def.full_name(),
                        member.name,
                        member.type_name
                    ),
                });
            }
        }
    }
    let mut out = BTreeMap::new();
    for def in defs {
        out.insert(def.full_name(), fingerprint(&structs, def, &mut Vec::new()));
    }
    Ok(out)
}

fn fingerprint(
    structs: &BTreeMap<String, StructDef>,
    def: &StructDef,
    parents: &mut Vec<String>,
) -> u64 {
    let name = def.full_name();
    if parents.contains(&name) {
        return 0;
    }
    parents.push(name);
    let mut hash = base_hash(def);
    for member in &def.members {
        if let Some(nested) = resolve(structs, def, &member.type_name) {
            hash = hash.wrapping_add(fingerprint(structs, nested, parents));
        }
    }
    parents.pop();
    hash.rotate_left(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The golden table of LCM_NOTES.md, checked against lcm-gen 1.3.1 and 1.5.3.
    const RTEST: &str = r#"
package rtest;
struct header_t { int64_t utime; int32_t seq; string frame_id; }
struct simple_t { int64_t utime; }
struct steering_cmd_t { int64_t utime; float steering_angle; float speed; boolean enabled; }
struct range_image_t {
    const int32_t MAX_WIDTH = 2048;
    header_t header; int32_t width; int32_t height; int32_t num_ranges;
    float ranges[num_ranges]; int16_t intensity[height][width]; double pose[4][4]; byte flags[3];
}
struct pair_t { header_t a; header_t b; simple_t c[2]; }
struct node_t { int32_t n; node_t children[n]; }
"#;

    const GOLDEN: [(&str, u64, u64); 6] = [
        ("header_t", 0xc5bd72ad6867ba8a, 0x8b7ae55ad0cf7515),
        ("simple_t", 0xa686a0e0f882d897, 0x4d0d41c1f105b12f),
        ("steering_cmd_t", 0xac61b07fcfa932c6, 0x58c360ff9f52658d),
        ("range_image_t", 0xe8569fc48331c3cc, 0xe7a30a3ea80271c2),
        ("pair_t", 0x8668ae5303c20135, 0xd4d775952ccd391d),
        ("node_t", 0x291281db12a3b1be, 0x522503b62547637c),
    ];

    #[test]
    fn the_golden_table_of_lcm_notes_is_reproduced() {
        let defs = parse(RTEST).unwrap();
        let fps = fingerprints(&defs).unwrap();
        for (name, base, fp) in GOLDEN {
            let def = defs.iter().find(|d| d.name == name).unwrap();
            assert_eq!(base_hash(def), base, "base hash of {name}");
            assert_eq!(fps[&format!("rtest.{name}")], fp, "fingerprint of {name}");
        }
    }

    #[test]
    fn constants_dimensions_and_comments_are_parsed() {
        let defs = parse(RTEST).unwrap();
        let image = defs.iter().find(|d| d.name == "range_image_t").unwrap();
        assert_eq!(image.constants[0].name, "MAX_WIDTH");
        assert_eq!(image.constants[0].value, "2048");
        let intensity = image
            .members
            .iter()
            .find(|m| m.name == "intensity")
            .unwrap();
        assert_eq!(
            intensity.dims,
            vec![
                Dim::Var {
                    member: "height".into()
                },
                Dim::Var {
                    member: "width".into()
                }
            ]
        );
        let defs = parse(
            "package p;\n// A thing.\nstruct a_t {\n  // above\n  int32_t n; // after\n  double x[n], y[3]; /* both */\n}\n",
        )
        .unwrap();
        assert_eq!(defs[0].doc, "A thing.");
        assert_eq!(defs[0].members[0].doc, "above\nafter");
        assert_eq!(defs[0].members.len(), 3);
        assert_eq!(
            defs[0].members[2].dims,
            vec![Dim::Const {
                size: 3,
                text: "3".into()
            }]
        );
    }

    #[test]
    fn mistakes_are_reported_with_their_line() {
        let err = parse("package p;\nstruct a_t {\n  double x[n];\n}\n").unwrap_err();
        assert_eq!(err.line, 3);
        assert!(err.message.contains("not an earlier member"), "{err}");
        let err = parse("package p;\nstruct a_t {\n  double x;\n  int32_t x;\n}\n").unwrap_err();
        assert!(err.message.contains("declared twice"), "{err}");
        let err = parse("package p;\nstruct a_t {\n  double x\n}\n").unwrap_err();
        assert_eq!(err.line, 4);
        assert!(parse("struct a_t { double x; ").is_err());
        let err = fingerprints(&parse("package p; struct a_t { b_t b; }").unwrap()).unwrap_err();
        assert!(err.message.contains("no .lcm file defines"), "{err}");
    }
}
