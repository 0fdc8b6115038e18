//! OpenUSD Gaussian splats: the `ParticleField3DGaussianSplat` prim of `UsdVol` (OpenUSD 25.11
//! and later; what 3dgrut exports), written as a `.usda` text layer and read from one.
//!
//! | attribute | USD type | content |
//! |---|---|---|
//! | `positions` | `point3f[]` | the means |
//! | `orientations` | `quatf[]` | unit quaternions, (w, x, y, z) in usda's text |
//! | `scales` | `float3[]` | linear standard deviations (not the `.ply`'s logarithms) |
//! | `opacities` | `float[]` | opacity after the sigmoid, in [0, 1] |
//! | `radiance:sphericalHarmonicsDegree` | `uniform int` | the SH degree d (the schema's fallback: 3) |
//! | `radiance:sphericalHarmonicsCoefficients` | `float3[]`, `elementSize` (d + 1)² | per particle, (d + 1)² RGB coefficients, DC first, in the `.ply`'s order within a band |
//!
//! The half-precision twins (`positionsh`, `orientationsh`, `scalesh`, `opacitiesh`,
//! `radiance:sphericalHarmonicsCoefficientsh`) are read where the float ones are absent, as the
//! schema asks. The colours are the display (sRGB-encoded) values 3DGS trains on: the writer
//! says so with `ColorSpaceAPI`'s `srgb_rec709_display`, as 3dgrut's exporter does.
//!
//! **Axes.** The writer stores the scene's own axes (a `.ply`'s, right-down-forward for a
//! COLMAP capture) under a `World` Xform with no transform, as 3dgrut's exporter does unless
//! asked to flip them; the stage's `upAxis` is USD's default `"Y"`. The reader places each
//! prim by the `xformOp`s of it and its ancestors, composed as `UsdGeomXformable` composes them
//! (`xformOpOrder`, first op outermost; `!invert!` and `!resetXformStack!`): `transform`,
//! `translate`, `scale`, `rotateX`/`Y`/`Z`, the six `rotateXYZ`… orders and `orient`. Splats
//! take a uniform scale, rotations and mirrors (the crate's private `placement` module); a non-uniform scale is
//! refused by name.
//!
//! **What the reader reads.** One text layer (`#usda 1.0`): every `def` prim of type
//! `ParticleField3DGaussianSplat` in it, outside `class` prims, `over`s and invisible prims,
//! each placed, joined into one scene (the highest SH degree; missing bands zero). It does not
//! follow composition (sublayers, references, payloads) or read time samples, variants or binary
//! crate files (`.usdc`, `.usdz`): those are refused, or noted where splats were found anyway,
//! with `usdcat --flatten -o scene.usda` as the way to a layer it reads. Other particle fields
//! (`ParticleField` with a surflet kernel: 3dgrut's 2DGS) are refused by name.

use crate::placement::Placement;
use crate::{Error, ErrorKind, read_file};
use glam::{DMat4, DQuat, DVec3, Quat, Vec3};
use splat_core::particle::{SH_MAX_COEFFS, SH_MAX_DEGREE, sh_coeff_count};
use splat_core::{Particle, Scene};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// The prim type of 3D Gaussian splats.
const SPLAT_TYPE: &str = "ParticleField3DGaussianSplat";
/// A binary crate file's first bytes.
const CRATE_MAGIC: &[u8] = b"PXR-USDC";
/// How to make a layer this reader reads.
const FLATTEN: &str = "flatten it to one text layer with OpenUSD's usdcat (its flatten option, writing a .usda)";

fn bad(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Usd(message.into())
}

/// What the reader made of a `.usda` layer.
#[derive(Clone, Debug)]
pub struct UsdRead {
    /// The splats of every `ParticleField3DGaussianSplat` prim, placed.
    pub scene: Scene,
    /// The prims read, by path.
    pub prims: Vec<String>,
    /// What the user should hear of (composition not followed, bands dropped, prims skipped).
    pub notes: Vec<String>,
}

impl UsdRead {
    /// The format detail `splat info` prints.
    pub fn describe(&self) -> String {
        let count = self.prims.len();
        format!("usda layer, {count} prim{}: {}", if count == 1 { "" } else { "s" }, self.prims.join(", "))
    }
}

/// Read a `.usda` (or text `.usd`) layer.
pub fn read_usd(path: &Path) -> Result<UsdRead, Error> {
    parse_usda(&read_file(path)?).map_err(|kind| Error::new(path, kind))
}

/// Write a scene as a `.usda` layer ([`encode_usda`]).
pub fn write_usda(path: &Path, scene: &Scene) -> Result<(), Error> {
    std::fs::write(path, encode_usda(scene)).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}

/// A scene as a `.usda` layer: `/World/gaussians`, a `ParticleField3DGaussianSplat` with every
/// attribute in f32, written to the shortest text that reads back to the same f32 (lossless).
/// Its `extent` bounds the particles' 3σ ellipsoids.
pub fn encode_usda(scene: &Scene) -> String {
    let d = scene.sh_degree.min(SH_MAX_DEGREE);
    let coefficients = sh_coeff_count(d);
    let extent = scene.particles.iter().fold(splat_core::particle::Aabb::EMPTY, |b, p| b.union(p.aabb(3.0)));
    let mut out = String::with_capacity(scene.particles.len() * (60 + 40 * coefficients));
    out.push_str(
        "#usda 1.0\n(\n    defaultPrim = \"World\"\n    doc = \"3D Gaussian splats written by splat\"\n    metersPerUnit = 1\n    upAxis = \"Y\"\n)\n\n",
    );
    out.push_str("def Xform \"World\"\n{\n    def ParticleField3DGaussianSplat \"gaussians\" (\n");
    out.push_str("        prepend apiSchemas = [\"ColorSpaceAPI\"]\n    )\n    {\n");
    out.push_str("        uniform token colorSpace:name = \"srgb_rec709_display\"\n");
    let v3 = |out: &mut String, v: Vec3| {
        let _ = write!(out, "({}, {}, {})", v.x, v.y, v.z);
    };
    let array = |out: &mut String, declaration: &str, items: &mut dyn Iterator<Item = String>| {
        let _ = write!(out, "        {declaration} = [");
        for (i, item) in items.enumerate() {
            if i > 0 {
                out.push_str(", ");
            }
            out.push_str(&item);
        }
        out.push(']');
    };
    let text = |v: Vec3| {
        let mut s = String::new();
        v3(&mut s, v);
        s
    };
    if !scene.particles.is_empty() {
        array(&mut out, "float3[] extent", &mut [extent.min, extent.max].into_iter().map(text));
        out.push('\n');
    }
    let particles = &scene.particles;
    array(&mut out, "point3f[] positions", &mut particles.iter().map(|p| text(p.mean)));
    out.push('\n');
    array(
        &mut out,
        "quatf[] orientations",
        &mut particles.iter().map(|p| {
            let q = p.rotation;
            format!("({}, {}, {}, {})", q.w, q.x, q.y, q.z)
        }),
    );
    out.push('\n');
    array(&mut out, "float3[] scales", &mut particles.iter().map(|p| text(p.scale)));
    out.push('\n');
    array(&mut out, "float[] opacities", &mut particles.iter().map(|p| p.opacity.to_string()));
    out.push('\n');
    let _ = writeln!(out, "        uniform int radiance:sphericalHarmonicsDegree = {d}");
    array(
        &mut out,
        "float3[] radiance:sphericalHarmonicsCoefficients",
        &mut particles.iter().flat_map(|p| p.sh.to_array()[..coefficients].to_vec().into_iter().map(text)),
    );
    let _ = write!(out, " (\n            elementSize = {coefficients}\n        )\n    }}\n}}\n");
    out
}

// ---------------------------------------------------------------------------------------------
// Tokens

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok<'a> {
    Punct(u8),
    Ident(&'a str),
    Number(&'a str),
    Str(&'a str),
    /// `<…>` and `@…@`.
    Reference(&'a str),
}

impl std::fmt::Display for Tok<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Tok::Punct(c) => write!(f, "'{}'", *c as char),
            Tok::Ident(s) | Tok::Number(s) => write!(f, "'{s}'"),
            Tok::Str(s) => write!(f, "\"{}\"", s.chars().take(40).collect::<String>()),
            Tok::Reference(s) => write!(f, "<{s}>"),
        }
    }
}

struct Lexer<'a> {
    text: &'a str,
    at: usize,
    line: usize,
    peeked: Option<(Option<Tok<'a>>, usize, usize)>,
}

impl<'a> Lexer<'a> {
    fn new(text: &'a str) -> Self {
        Self { text, at: 0, line: 1, peeked: None }
    }

    fn error(&self, message: impl std::fmt::Display) -> ErrorKind {
        bad(format!("line {}: {message}", self.line))
    }

    fn peek(&mut self) -> Result<Option<Tok<'a>>, ErrorKind> {
        if self.peeked.is_none() {
            let (at, line) = (self.at, self.line);
            let tok = self.lex()?;
            self.peeked = Some((tok, self.at, self.line));
            (self.at, self.line) = (at, line);
        }
        Ok(self.peeked.expect("just set").0)
    }

    fn next(&mut self) -> Result<Option<Tok<'a>>, ErrorKind> {
        if let Some((tok, at, line)) = self.peeked.take() {
            (self.at, self.line) = (at, line);
            return Ok(tok);
        }
        self.lex()
    }

    /// The next token, or an error naming what was expected.
    fn want(&mut self, what: &str) -> Result<Tok<'a>, ErrorKind> {
        self.next()?.ok_or_else(|| self.error(format!("the layer ends where {what} should be")))
    }

    fn expect(&mut self, c: u8) -> Result<(), ErrorKind> {
        match self.want(&format!("'{}'", c as char))? {
            Tok::Punct(p) if p == c => Ok(()),
            other => Err(self.error(format!("expected '{}', found {other}", c as char))),
        }
    }

    fn lex(&mut self) -> Result<Option<Tok<'a>>, ErrorKind> {
        let b = self.text.as_bytes();
        loop {
            match b.get(self.at) {
                None => return Ok(None),
                Some(b'\n') => {
                    self.line += 1;
                    self.at += 1;
                }
                Some(c) if c.is_ascii_whitespace() => self.at += 1,
                Some(b'#') => {
                    while self.at < b.len() && b[self.at] != b'\n' {
                        self.at += 1;
                    }
                }
                Some(_) => break,
            }
        }
        let start = self.at;
        let c = b[start];
        let run = |from: usize, ok: &dyn Fn(u8) -> bool| {
            let mut end = from;
            while end < b.len() && ok(b[end]) {
                end += 1;
            }
            end
        };
        let is_ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b':' || c == b'.';
        let tok = match c {
            b'"' | b'\'' => return self.string(c).map(Some),
            b'<' | b'@' => {
                let close = if c == b'<' { '>' } else { '@' };
                let end = self.text[start + 1..]
                    .find(close)
                    .ok_or_else(|| self.error(format!("'{}' is never closed", c as char)))?;
                self.line += self.text[start..start + 1 + end].matches('\n').count();
                self.at = start + end + 2;
                return Ok(Some(Tok::Reference(&self.text[start + 1..start + 1 + end])));
            }
            b'-' | b'+' if b.get(start + 1).is_some_and(|c| c.is_ascii_alphabetic()) => {
                self.at = run(start + 1, &is_ident);
                Tok::Ident(&self.text[start..self.at])
            }
            b'0'..=b'9' | b'-' | b'+' | b'.' => {
                self.at = run(start + 1, &|c: u8| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'-' | b'+'));
                Tok::Number(&self.text[start..self.at])
            }
            c if c.is_ascii_alphabetic() || c == b'_' => {
                self.at = run(start, &is_ident);
                Tok::Ident(&self.text[start..self.at])
            }
            b'(' | b')' | b'[' | b']' | b'{' | b'}' | b'=' | b',' | b';' | b':' | b'&' => {
                self.at += 1;
                Tok::Punct(c)
            }
            other => return Err(self.error(format!("unexpected character {:?}", other as char))),
        };
        Ok(Some(tok))
    }

    /// A string in `quote`, single or tripled; its text between the quotes, escapes kept.
    fn string(&mut self, quote: u8) -> Result<Tok<'a>, ErrorKind> {
        let b = self.text.as_bytes();
        let start = self.at;
        let triple = b.get(start + 1) == Some(&quote) && b.get(start + 2) == Some(&quote);
        let open = if triple { 3 } else { 1 };
        let mut i = start + open;
        loop {
            match b.get(i) {
                None => return Err(self.error("a string is never closed")),
                Some(b'\\') => i += 2,
                Some(b'\n') if !triple => return Err(self.error("a string runs past the end of its line")),
                Some(&c) if c == quote && (!triple || b[i..].starts_with(&[quote; 3])) => break,
                Some(_) => i += 1,
            }
        }
        self.line += self.text[start..i].matches('\n').count();
        self.at = i + open;
        Ok(Tok::Str(&self.text[start + open..i]))
    }
}

// ---------------------------------------------------------------------------------------------
// Values

/// How an attribute's numbers are parsed: as f32 (float, half, point3f, quatf …) or f64
/// (double, matrix4d, quatd), each token straight to its type.
#[derive(Clone, Copy, PartialEq)]
enum Precision {
    Single,
    Double,
    Int,
}

/// A numeric value, flattened: `items` elements of `arity` numbers each (1 for a scalar,
/// 16 for a matrix4d), and whether it was written as an array.
#[derive(Clone, Debug)]
struct Numbers {
    data: Vec<f64>,
    arity: usize,
    array: bool,
}

/// A value the reader keeps.
#[derive(Clone, Debug)]
enum Value {
    Numbers(Numbers),
    Strings(Vec<String>),
    /// `None`: a blocked value, as if unauthored.
    Blocked,
}

fn number(lx: &Lexer, token: &str, precision: Precision) -> Result<f64, ErrorKind> {
    let word = match token {
        "inf" | "+inf" => Some(f64::INFINITY),
        "-inf" => Some(f64::NEG_INFINITY),
        "nan" => Some(f64::NAN),
        _ => None,
    };
    let parsed = match precision {
        _ if word.is_some() => word,
        Precision::Single => token.parse::<f32>().ok().map(f64::from),
        Precision::Double => token.parse::<f64>().ok(),
        Precision::Int => token.parse::<i64>().ok().map(|v| v as f64),
    };
    parsed.ok_or_else(|| lx.error(format!("'{token}' is not a number")))
}

/// One element: a number or a tuple (nested tuples flattened, as matrix4d's rows are).
fn element(lx: &mut Lexer, precision: Precision, out: &mut Vec<f64>) -> Result<(), ErrorKind> {
    match lx.want("a value")? {
        Tok::Number(t) | Tok::Ident(t) => out.push(number(lx, t, precision)?),
        Tok::Punct(b'(') => loop {
            if lx.peek()? == Some(Tok::Punct(b')')) {
                lx.next()?;
                break;
            }
            element(lx, precision, out)?;
            match lx.want("',' or ')'")? {
                Tok::Punct(b',') => {}
                Tok::Punct(b')') => break,
                other => return Err(lx.error(format!("expected ',' or ')' in a tuple, found {other}"))),
            }
        },
        other => return Err(lx.error(format!("expected a number or a tuple, found {other}"))),
    }
    Ok(())
}

/// A numeric value of `precision`: a scalar, a tuple or an array of either.
fn numbers(lx: &mut Lexer, precision: Precision) -> Result<Value, ErrorKind> {
    let mut data = Vec::new();
    match lx.peek()? {
        Some(Tok::Ident("None")) => {
            lx.next()?;
            Ok(Value::Blocked)
        }
        Some(Tok::Punct(b'[')) => {
            lx.next()?;
            let mut arity = None;
            loop {
                if lx.peek()? == Some(Tok::Punct(b']')) {
                    lx.next()?;
                    break;
                }
                let before = data.len();
                element(lx, precision, &mut data)?;
                let n = data.len() - before;
                if *arity.get_or_insert(n) != n {
                    return Err(lx.error(format!("an array mixes elements of {} and {n} numbers", arity.unwrap_or(0))));
                }
                match lx.want("',' or ']'")? {
                    Tok::Punct(b',') => {}
                    Tok::Punct(b']') => break,
                    other => return Err(lx.error(format!("expected ',' or ']' in an array, found {other}"))),
                }
            }
            Ok(Value::Numbers(Numbers { arity: arity.unwrap_or(1), data, array: true }))
        }
        _ => {
            element(lx, precision, &mut data)?;
            Ok(Value::Numbers(Numbers { arity: data.len(), data, array: false }))
        }
    }
}

/// A string or token value, or an array of them.
fn strings(lx: &mut Lexer) -> Result<Value, ErrorKind> {
    match lx.want("a value")? {
        Tok::Str(s) => Ok(Value::Strings(vec![s.to_string()])),
        Tok::Ident("None") => Ok(Value::Blocked),
        Tok::Punct(b'[') => {
            let mut out = Vec::new();
            loop {
                match lx.want("a string or ']'")? {
                    Tok::Punct(b']') => break,
                    Tok::Punct(b',') => {}
                    Tok::Str(s) => out.push(s.to_string()),
                    other => return Err(lx.error(format!("expected a string in an array, found {other}"))),
                }
            }
            Ok(Value::Strings(out))
        }
        other => Err(lx.error(format!("expected a string, found {other}"))),
    }
}

/// Skip a value of any kind: a token, or a bracketed group with everything inside it.
fn skip_value(lx: &mut Lexer) -> Result<(), ErrorKind> {
    match lx.want("a value")? {
        Tok::Punct(open @ (b'(' | b'[' | b'{')) => skip_group(lx, open),
        Tok::Punct(c) if c != b'&' => Err(lx.error(format!("expected a value, found '{}'", c as char))),
        _ => Ok(()),
    }
}

/// Skip to the bracket closing `open` (already read), nested groups included.
fn skip_group(lx: &mut Lexer, open: u8) -> Result<(), ErrorKind> {
    let mut depth = vec![open];
    while let Some(&top) = depth.last() {
        match lx.want("a closing bracket")? {
            Tok::Punct(c @ (b'(' | b'[' | b'{')) => depth.push(c),
            Tok::Punct(c @ (b')' | b']' | b'}')) => {
                let expected = match top {
                    b'(' => b')',
                    b'[' => b']',
                    _ => b'}',
                };
                if c != expected {
                    return Err(lx.error(format!("'{}' closes '{}'", c as char, top as char)));
                }
                depth.pop();
            }
            _ => {}
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Prims

#[derive(Default)]
struct Prim {
    specifier: String,
    type_name: Option<String>,
    name: String,
    line: usize,
    attributes: HashMap<String, Value>,
    /// Attributes authored only as time samples.
    animated: Vec<String>,
    children: Vec<Prim>,
}

/// Whether the reader keeps attribute `name`'s value.
fn kept(name: &str) -> bool {
    matches!(
        name,
        "positions"
            | "positionsh"
            | "orientations"
            | "orientationsh"
            | "scales"
            | "scalesh"
            | "opacities"
            | "opacitiesh"
            | "radiance:sphericalHarmonicsDegree"
            | "radiance:sphericalHarmonicsCoefficients"
            | "radiance:sphericalHarmonicsCoefficientsh"
            | "xformOpOrder"
            | "visibility"
    ) || name.starts_with("xformOp:")
}

/// The precision a USD value type parses at, or `None` for a string-like type.
fn precision(type_name: &str) -> Option<Precision> {
    let base = type_name.trim_end_matches(|c: char| c.is_ascii_digit());
    match base {
        "token" | "string" | "asset" => None,
        "int" | "uint" | "int64" | "uint64" => Some(Precision::Int),
        t if t.starts_with("double") || t.starts_with("matrix") || t.ends_with('d') => Some(Precision::Double),
        _ => Some(Precision::Single),
    }
}

/// Composition arcs found, to say why a layer holds nothing this reader reads.
#[derive(Default)]
struct Arcs(Vec<String>);

impl Arcs {
    fn note(&mut self, what: &str) {
        if !self.0.iter().any(|a| a == what) {
            self.0.push(what.to_string());
        }
    }
}

/// Skip a metadata block `( … )` (its '(' already read), noting composition arcs in it.
fn metadata(lx: &mut Lexer, arcs: &mut Arcs) -> Result<(), ErrorKind> {
    let mut depth = 1usize;
    while depth > 0 {
        match lx.want("')' closing the metadata")? {
            Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
            Tok::Punct(b')' | b']' | b'}') => depth -= 1,
            Tok::Ident(
                word @ ("subLayers" | "references" | "payload" | "inherits" | "specializes" | "variantSets"),
            ) if depth == 1 => arcs.note(word),
            _ => {}
        }
    }
    Ok(())
}

/// A prim (its specifier word already read) with everything inside it.
fn prim(lx: &mut Lexer, specifier: &str, arcs: &mut Arcs) -> Result<Prim, ErrorKind> {
    let line = lx.line;
    let mut p = Prim { specifier: specifier.to_string(), line, ..Prim::default() };
    loop {
        match lx.want("the prim's name")? {
            Tok::Ident(t) => p.type_name = Some(t.to_string()),
            Tok::Str(name) => {
                p.name = name.to_string();
                break;
            }
            other => return Err(lx.error(format!("expected a prim type or name after '{specifier}', found {other}"))),
        }
    }
    if lx.peek()? == Some(Tok::Punct(b'(')) {
        lx.next()?;
        metadata(lx, arcs)?;
    }
    lx.expect(b'{')?;
    body(lx, &mut p, arcs)?;
    Ok(p)
}

/// A prim's contents up to its closing '}'.
fn body(lx: &mut Lexer, p: &mut Prim, arcs: &mut Arcs) -> Result<(), ErrorKind> {
    loop {
        match lx.want("'}' closing the prim")? {
            Tok::Punct(b'}') => return Ok(()),
            Tok::Punct(b';') => {}
            Tok::Ident(s @ ("def" | "over" | "class")) => p.children.push(prim(lx, s, arcs)?),
            Tok::Ident("variantSet") => {
                arcs.note("variantSets");
                lx.want("the variant set's name")?;
                lx.expect(b'=')?;
                skip_value(lx)?;
            }
            Tok::Ident("reorder") => {
                lx.want("what to reorder")?;
                lx.expect(b'=')?;
                skip_value(lx)?;
            }
            Tok::Ident(first) => property(lx, first, p, arcs)?,
            other => return Err(lx.error(format!("expected a property or a prim, found {other}"))),
        }
    }
}

/// A property (its first word read): `[custom] [uniform|varying] TYPE[[]] NAME [= VALUE]
/// [( metadata )]`, `NAME.timeSamples = {…}`, `NAME.connect = …` or a relationship.
fn property(lx: &mut Lexer, first: &str, p: &mut Prim, arcs: &mut Arcs) -> Result<(), ErrorKind> {
    let mut word = first;
    while matches!(word, "custom" | "uniform" | "varying" | "config" | "prepend" | "append" | "add" | "delete") {
        word = match lx.want("a property")? {
            Tok::Ident(w) => w,
            other => return Err(lx.error(format!("expected a property type, found {other}"))),
        };
    }
    let is_rel = word == "rel";
    let type_name = word;
    let mut array = false;
    if lx.peek()? == Some(Tok::Punct(b'[')) {
        lx.next()?;
        lx.expect(b']')?;
        array = true;
    }
    let name = match lx.want("the property's name")? {
        Tok::Ident(n) => n,
        other => return Err(lx.error(format!("expected the name of a {type_name} property, found {other}"))),
    };
    let (name, suffix) = match name.split_once('.') {
        Some((n, s)) => (n, Some(s)),
        None => (name, None),
    };
    if lx.peek()? == Some(Tok::Punct(b'=')) {
        lx.next()?;
        let keep = kept(name) && !is_rel && suffix.is_none();
        if keep {
            let value = match precision(type_name) {
                Some(precision) => numbers(lx, precision)?,
                None => strings(lx)?,
            };
            if let Value::Numbers(n) = &value
                && n.array != array
            {
                let written = if n.array { "an array" } else { "a single value" };
                return Err(lx.error(format!(
                    "{name} is declared {type_name}{} but holds {written}",
                    ["", "[]"][usize::from(array)]
                )));
            }
            p.attributes.insert(name.to_string(), value);
        } else {
            if suffix == Some("timeSamples") && kept(name) {
                p.animated.push(name.to_string());
            }
            skip_value(lx)?;
        }
    }
    if lx.peek()? == Some(Tok::Punct(b'(')) {
        lx.next()?;
        metadata(lx, arcs)?;
    }
    Ok(())
}

/// The layer's prims (its header checked).
fn layer(text: &str, arcs: &mut Arcs) -> Result<Vec<Prim>, ErrorKind> {
    let mut lx = Lexer::new(text);
    if lx.peek()? == Some(Tok::Punct(b'(')) {
        lx.next()?;
        metadata(&mut lx, arcs)?;
    }
    let mut prims = Vec::new();
    while let Some(tok) = lx.next()? {
        match tok {
            Tok::Ident(s @ ("def" | "over" | "class")) => prims.push(prim(&mut lx, s, arcs)?),
            other => return Err(lx.error(format!("expected a prim ('def', 'over' or 'class'), found {other}"))),
        }
    }
    Ok(prims)
}

// ---------------------------------------------------------------------------------------------
// Transforms

/// The matrix (column vectors, x' = M x) of `xformOp:KIND[:suffix]` with value `value`.
fn op_matrix(op: &str, value: &Numbers) -> Result<DMat4, String> {
    let kind = op.strip_prefix("xformOp:").unwrap_or(op).split(':').next().unwrap_or("");
    let v = &value.data;
    let want = |n: usize| {
        if v.len() == n && !value.array { Ok(()) } else { Err(format!("{op} holds {} numbers, not {n}", v.len())) }
    };
    let axis_angle = |axis: DVec3| -> Result<DMat4, String> {
        want(1)?;
        Ok(DMat4::from_axis_angle(axis, v[0].to_radians()))
    };
    Ok(match kind {
        "transform" => {
            want(16)?;
            // usda writes a matrix row by row for row vectors (x' = x M): its rows are the
            // columns of the column-vector matrix.
            DMat4::from_cols_array(v.as_slice().try_into().expect("16 numbers"))
        }
        "translate" => {
            want(3)?;
            DMat4::from_translation(DVec3::new(v[0], v[1], v[2]))
        }
        "scale" => {
            want(3)?;
            DMat4::from_scale(DVec3::new(v[0], v[1], v[2]))
        }
        "rotateX" => axis_angle(DVec3::X)?,
        "rotateY" => axis_angle(DVec3::Y)?,
        "rotateZ" => axis_angle(DVec3::Z)?,
        "orient" => {
            want(4)?;
            DMat4::from_quat(DQuat::from_xyzw(v[1], v[2], v[3], v[0]).normalize())
        }
        rotate if rotate.len() == 9 && rotate.starts_with("rotate") => {
            want(3)?;
            // rotateABC turns about A first, then B, then C: M = R_C R_B R_A.
            let mut m = DMat4::IDENTITY;
            for (axis, angle) in rotate[6..].chars().zip(v) {
                let r = match axis {
                    'X' => DMat4::from_rotation_x(angle.to_radians()),
                    'Y' => DMat4::from_rotation_y(angle.to_radians()),
                    'Z' => DMat4::from_rotation_z(angle.to_radians()),
                    _ => return Err(format!("{op} is not a rotation order")),
                };
                m = r * m;
            }
            m
        }
        _ => return Err(format!("{op} is an xformOp this reader does not compose")),
    })
}

/// A prim's local transform and whether it resets its parents' (`!resetXformStack!`).
fn local_transform(p: &Prim) -> Result<(DMat4, bool), String> {
    let order = match p.attributes.get("xformOpOrder") {
        Some(Value::Strings(order)) => order.clone(),
        _ => return Ok((DMat4::IDENTITY, false)),
    };
    let mut m = DMat4::IDENTITY;
    let mut reset = false;
    for (i, entry) in order.iter().enumerate() {
        if entry == "!resetXformStack!" {
            if i != 0 {
                return Err("!resetXformStack! is not first in xformOpOrder".into());
            }
            reset = true;
            continue;
        }
        let (op, invert) = match entry.strip_prefix("!invert!") {
            Some(op) => (op, true),
            None => (entry.as_str(), false),
        };
        if p.animated.iter().any(|a| a == op) && !p.attributes.contains_key(op) {
            return Err(format!("{op} is animated (time samples only), which this reader does not read"));
        }
        let value = match p.attributes.get(op) {
            Some(Value::Numbers(n)) => n,
            _ => return Err(format!("xformOpOrder names {op}, which holds no value")),
        };
        let mut op_m = op_matrix(op, value)?;
        if invert {
            if op_m.determinant().abs() < 1e-300 {
                return Err(format!("!invert!{op} inverts a singular matrix"));
            }
            op_m = op_m.inverse();
        }
        m *= op_m;
    }
    Ok((m, reset))
}

// ---------------------------------------------------------------------------------------------
// Splats

/// The f32 elements of the first of `names` that `p` holds, each of `arity` numbers.
fn attribute<'p>(
    p: &'p Prim,
    names: &[&'static str],
    arity: usize,
) -> Result<Option<(&'static str, &'p [f64])>, String> {
    for &name in names {
        match p.attributes.get(name) {
            None | Some(Value::Blocked) => continue,
            Some(Value::Strings(_)) => return Err(format!("{name} holds text, not numbers")),
            Some(Value::Numbers(n)) => {
                if n.arity != arity && !n.data.is_empty() {
                    return Err(format!("{name} has elements of {} numbers, not {arity}", n.arity));
                }
                return Ok(Some((name, &n.data)));
            }
        }
    }
    if let Some(name) = names.iter().find(|n| p.animated.iter().any(|a| a == *n)) {
        return Err(format!("{name} is animated (time samples only), which this reader does not read"));
    }
    Ok(None)
}

/// The splats of prim `p` (at `path`), placed by `world`; their SH degree and notes.
fn splats(p: &Prim, path: &str, world: DMat4, notes: &mut Vec<String>) -> Result<(Vec<Particle>, u8), String> {
    let required = |names: &[&'static str], arity: usize| -> Result<(&'static str, &[f64]), String> {
        attribute(p, names, arity)?.ok_or_else(|| format!("it has no {}", names[0]))
    };
    let (_, positions) = required(&["positions", "positionsh"], 3)?;
    let n = positions.len() / 3;
    let (_, orientations) = required(&["orientations", "orientationsh"], 4)?;
    let (_, scales) = required(&["scales", "scalesh"], 3)?;
    let (_, opacities) = required(&["opacities", "opacitiesh"], 1)?;
    let degree = match p.attributes.get("radiance:sphericalHarmonicsDegree") {
        Some(Value::Numbers(v)) if v.data.len() == 1 && !v.array => {
            let d = v.data[0];
            if !(0.0..=16.0).contains(&d) {
                return Err(format!("radiance:sphericalHarmonicsDegree {d} is not a degree"));
            }
            d as usize
        }
        Some(Value::Numbers(_)) | Some(Value::Strings(_)) => {
            return Err("radiance:sphericalHarmonicsDegree is not one integer".into());
        }
        None | Some(Value::Blocked) => 3,
    };
    let coefficient_names = ["radiance:sphericalHarmonicsCoefficients", "radiance:sphericalHarmonicsCoefficientsh"];
    let (sh_name, sh) = required(&coefficient_names, 3)?;
    let per = (degree + 1) * (degree + 1);
    for (name, len, each) in
        [("orientations", orientations.len(), 4), ("scales", scales.len(), 3), ("opacities", opacities.len(), 1)]
    {
        if len != n * each {
            return Err(format!("{n} positions but {} {name}", len / each));
        }
    }
    if sh.len() != n * per * 3 {
        return Err(format!(
            "{sh_name} holds {} coefficients, not {n} particles × {per} (degree {degree})",
            sh.len() / 3
        ));
    }
    let kept_degree = degree.min(usize::from(SH_MAX_DEGREE));
    if kept_degree < degree {
        notes.push(format!("{path}: SH degree {degree} read with bands above {SH_MAX_DEGREE} dropped"));
    }
    let placement = Placement::of(world.as_mat4()).map_err(|m| format!("the prim's world transform: {m}"))?;
    let f = |v: f64| v as f32;
    let mut particles = Vec::with_capacity(n);
    for i in 0..n {
        let mean = Vec3::new(f(positions[3 * i]), f(positions[3 * i + 1]), f(positions[3 * i + 2]));
        let scale = Vec3::new(f(scales[3 * i]), f(scales[3 * i + 1]), f(scales[3 * i + 2]));
        let o = &orientations[4 * i..4 * i + 4];
        let rotation = Quat::from_xyzw(f(o[1]), f(o[2]), f(o[3]), f(o[0]));
        let mut coefficients = [Vec3::ZERO; SH_MAX_COEFFS];
        for (k, c) in coefficients.iter_mut().take(sh_coeff_count(kept_degree as u8)).enumerate() {
            let at = 3 * (i * per + k);
            *c = Vec3::new(f(sh[at]), f(sh[at + 1]), f(sh[at + 2]));
        }
        let (mean, scale, rotation, coefficients) = placement.place(mean, scale, rotation, coefficients);
        let particle = Particle::new(mean, scale, rotation, f(opacities[i]), coefficients)
            .map_err(|error| format!("particle {i}: {error}"))?;
        particles.push(particle);
    }
    Ok((particles, kept_degree as u8))
}

/// Walk the prims under `parent` (path, world transform), collecting splats.
fn collect(
    prims: &[Prim],
    parent: &str,
    world: DMat4,
    found: &mut Vec<(String, Vec<Particle>, u8)>,
    notes: &mut Vec<String>,
) -> Result<(), ErrorKind> {
    for p in prims {
        let path = format!("{parent}/{}", p.name);
        let at = |m: String| bad(format!("prim {path} (line {}): {m}", p.line));
        if p.specifier != "def" {
            continue;
        }
        if matches!(p.attributes.get("visibility"), Some(Value::Strings(v)) if v.first().is_some_and(|v| v == "invisible"))
        {
            notes.push(format!("{path} is invisible: skipped"));
            continue;
        }
        let (local, reset) = local_transform(p).map_err(at)?;
        let here = if reset { local } else { world * local };
        match p.type_name.as_deref() {
            Some(SPLAT_TYPE) => {
                let (particles, degree) = splats(p, &path, here, notes).map_err(at)?;
                found.push((path.clone(), particles, degree));
            }
            Some(t) if t.starts_with("ParticleField") => {
                return Err(at(format!(
                    "a {t} is not read: only {SPLAT_TYPE} (3D Gaussians) is (a ParticleField with a surflet kernel holds 2DGS surfels)"
                )));
            }
            _ => {}
        }
        collect(&p.children, &path, here, found, notes)?;
    }
    Ok(())
}

/// Parse a `.usda` layer's bytes.
pub fn parse_usda(bytes: &[u8]) -> Result<UsdRead, ErrorKind> {
    if bytes.starts_with(CRATE_MAGIC) {
        return Err(bad(format!("a binary crate file (usdc), which this reader does not read: {FLATTEN}")));
    }
    if bytes.starts_with(b"PK\x03\x04") {
        return Err(bad(format!("a .usdz package, which this reader does not read: unzip it, then {FLATTEN}")));
    }
    let text = std::str::from_utf8(bytes).map_err(|e| bad(format!("not UTF-8 text ({e}): not a usda layer")))?;
    if !(text.starts_with("#usda ") || text.starts_with("#usda\t")) {
        return Err(bad("the layer does not start with '#usda 1.0': not a usda text layer"));
    }
    let mut arcs = Arcs::default();
    let prims = layer(text, &mut arcs)?;
    let mut found = Vec::new();
    let mut notes = Vec::new();
    collect(&prims, "", DMat4::IDENTITY, &mut found, &mut notes)?;
    let composition = (!arcs.0.is_empty()).then(|| arcs.0.join(", "));
    if found.is_empty() {
        let why = composition
            .map_or(String::new(), |c| format!(" ({c} not followed: this reader reads one layer; {FLATTEN})"));
        return Err(bad(format!("the layer holds no {SPLAT_TYPE} prim{why}")));
    }
    if let Some(c) = composition {
        notes.push(format!("{c} not followed: only this layer's splats are read ({FLATTEN} to read them all)"));
    }
    let degree = found.iter().map(|(_, _, d)| *d).max().unwrap_or(0);
    let prims_read = found.iter().map(|(path, _, _)| path.clone()).collect();
    let particles = found.into_iter().flat_map(|(_, p, _)| p).collect::<Vec<_>>();
    if particles.is_empty() {
        return Err(bad(format!("its {SPLAT_TYPE} prims hold no particles")));
    }
    Ok(UsdRead { scene: Scene::new(particles, degree), prims: prims_read, notes })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let particles = (0..5)
            .map(|i| {
                let coefficients: [Vec3; 16] =
                    std::array::from_fn(|k| Vec3::new(0.1 * k as f32 - 0.37 * i as f32, 1e-7 * k as f32, -0.02));
                Particle::new(
                    Vec3::new(0.1 * i as f32, -3.3e-5, 1234.5678),
                    Vec3::new(0.01, 0.2 + i as f32, 3e-4),
                    Quat::from_euler(glam::EulerRot::XYZ, 0.4 * i as f32, -0.7, 1.1).normalize(),
                    0.1 + 0.2 * i as f32,
                    coefficients,
                )
                .unwrap()
            })
            .collect();
        Scene::new(particles, 3)
    }

    #[test]
    fn usda_round_trips_losslessly() {
        let s = scene();
        let read = parse_usda(encode_usda(&s).as_bytes()).unwrap();
        assert_eq!(read.prims, ["/World/gaussians"]);
        assert_eq!(read.scene.sh_degree, 3);
        for (a, b) in s.particles.iter().zip(&read.scene.particles) {
            assert_eq!(a.mean, b.mean);
            assert_eq!(a.scale, b.scale);
            assert_eq!(a.opacity, b.opacity);
            assert_eq!(a.sh.as_slice(), b.sh.as_slice());
            assert!(a.rotation.dot(b.rotation) > 1.0 - 1e-7);
        }
        let low = Scene::new(s.particles.clone(), 1);
        let text = encode_usda(&low);
        assert!(text.contains("elementSize = 4"));
        assert_eq!(parse_usda(text.as_bytes()).unwrap().scene.sh_degree, 1);
    }

    /// USD composes xformOpOrder with the first op outermost: translate, then rotate, then
    /// scale applies the scale to points first.
    #[test]
    fn xform_ops_compose_as_usd_composes_them() {
        let text = r#"#usda 1.0
def Xform "A" {
    double3 xformOp:translate = (1, 2, 3)
    float xformOp:rotateZ = 90
    float3 xformOp:scale = (2, 2, 2)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateZ", "xformOp:scale"]
    def ParticleField3DGaussianSplat "g" {
        point3f[] positions = [(1, 0, 0)]
        quatf[] orientations = [(1, 0, 0, 0)]
        float3[] scales = [(0.1, 0.1, 0.1)]
        float[] opacities = [0.5]
        uniform int radiance:sphericalHarmonicsDegree = 0
        float3[] radiance:sphericalHarmonicsCoefficients = [(0.5, 0.5, 0.5)]
    }
}
"#;
        let p = &parse_usda(text.as_bytes()).unwrap().scene.particles[0];
        // (1, 0, 0) scaled to (2, 0, 0), turned to (0, 2, 0), moved to (1, 4, 3).
        assert!((p.mean - Vec3::new(1.0, 4.0, 3.0)).length() < 1e-5, "{}", p.mean);
        assert!((p.scale - Vec3::splat(0.2)).length() < 1e-6);
    }

    #[test]
    fn bad_layers_are_refused_with_the_problem_named() {
        let good = encode_usda(&scene());
        let cases: [(String, &str); 8] = [
            ("PXR-USDC\0\0".into(), "binary crate file"),
            ("def Xform \"A\" {}".into(), "does not start with '#usda 1.0'"),
            ("#usda 1.0\ndef Xform \"A\" {}\n".into(), "holds no ParticleField3DGaussianSplat prim"),
            ("#usda 1.0\n(\n subLayers = [@other.usda@]\n)\ndef Xform \"A\" {}\n".into(), "subLayers not followed"),
            (good.replace("float[] opacities = [", "float[] opacities = [0.5, "), "5 positions but 6 opacities"),
            (
                good.replace("(\n            elementSize", "(\n elementSize")
                    .replace("sphericalHarmonicsDegree = 3", "sphericalHarmonicsDegree = 2"),
                "not 5 particles × 9 (degree 2)",
            ),
            (good.replace("point3f[] positions = [(", "point3f[] positions = [(1, "), "mixes elements"),
            (good[..good.len() / 2].to_string(), "the layer ends"),
        ];
        for (text, expected) in cases {
            let e = parse_usda(text.as_bytes()).unwrap_err().to_string();
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
        let stretched = good.replace(
            "def Xform \"World\"\n{\n",
            "def Xform \"World\"\n{\n    float3 xformOp:scale = (1, 2, 1)\n    uniform token[] xformOpOrder = [\"xformOp:scale\"]\n",
        );
        let e = parse_usda(stretched.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("uniform scale only") && e.contains("/World/gaussians"), "{e}");
        let surfels = good.replace("def ParticleField3DGaussianSplat", "def ParticleField");
        assert!(parse_usda(surfels.as_bytes()).unwrap_err().to_string().contains("a ParticleField is not read"));
    }
}
