//! A line-by-line check of OBJ and MTL text before tobj parses it (DESIGN.md §7: OBJ/MTL validation).
//!
//! tobj reports errors without a line number, accepts NaN and infinity as coordinates, and
//! panics on some malformed MTL lines (4.0.5 unwraps a colour with fewer than three numbers).
//! This pass rejects all of that first, naming file and line, so what reaches tobj is well formed.

use std::path::Path;
use std::str::SplitWhitespace;

use crate::error::SceneError;
use crate::map_kd;

/// What the OBJ refers to, found while checking it.
#[derive(Debug, Default)]
pub struct ObjSummary {
    /// `mtllib` arguments, as written.
    pub material_libraries: Vec<String>,
}

/// Element counts defined so far, for resolving face indices (1-based, or negative = relative).
#[derive(Default)]
struct Defined {
    positions: usize,
    texcoords: usize,
    normals: usize,
}

pub fn check_obj(file: &Path, text: &str) -> Result<ObjSummary, SceneError> {
    let mut summary = ObjSummary::default();
    let mut defined = Defined::default();
    for (at, line, mut words) in numbered_lines(file, text) {
        match words.next() {
            Some("v") => {
                at.finite_numbers(&mut words, 3, 3)?;
                // An optional w (divides x, y, z) or an RGB colour.
                match at.finite_numbers(&mut words, 0, 3)?.as_slice() {
                    [w] if *w == 0.0 => return Err(at.syntax("vertex weight w is zero")),
                    [_, _] => return Err(at.syntax("a vertex takes x y z, then w or r g b")),
                    _ if words.next().is_some() => {
                        return Err(at.syntax("a vertex takes at most 6 numbers"));
                    }
                    _ => {}
                }
                defined.positions += 1;
            }
            Some("vt") => {
                at.finite_numbers(&mut words, 2, 3)?;
                defined.texcoords += 1;
            }
            Some("vn") => {
                at.finite_numbers(&mut words, 3, 3)?;
                defined.normals += 1;
            }
            Some("f") => at.corners(words, &defined, 3)?,
            // tobj parses lines like faces, then drops them (`ignore_lines`).
            Some("l") => at.corners(words, &defined, 2)?,
            Some("mtllib") => summary.material_libraries.push(at.rest(line, "mtllib")?),
            Some("usemtl") => {
                at.rest(line, "usemtl")?;
            }
            _ => {}
        }
    }
    Ok(summary)
}

/// Checks an MTL file; returns the names of the materials it defines, in order.
pub fn check_mtl(file: &Path, text: &str) -> Result<Vec<String>, SceneError> {
    let mut materials = Vec::new();
    for (at, line, mut words) in numbered_lines(file, text) {
        match words.next() {
            Some("newmtl") => materials.push(at.rest(line, "newmtl")?),
            // Options and file name, as the loader will read them (DESIGN.md §5).
            Some("map_Kd") => {
                map_kd::parse(&at.rest(line, "map_Kd")?).map_err(|e| at.syntax(&e))?;
            }
            Some("Ka" | "Kd" | "Ks" | "Ke") => {
                let rgb = at.finite_numbers(&mut words, 3, 3)?;
                if rgb.iter().any(|c| *c < 0.0) {
                    return Err(at.syntax("negative colour"));
                }
            }
            Some("Ns" | "Ni" | "d") => {
                at.finite_numbers(&mut words, 1, 1)?;
            }
            Some("illum") => {
                words
                    .next()
                    .and_then(|w| w.parse::<u8>().ok())
                    .ok_or_else(|| at.syntax("illum needs an integer 0-255"))?;
            }
            _ => {}
        }
    }
    Ok(materials)
}

/// Each line of `text` with its place in `file` (numbered from 1) and its words.
fn numbered_lines<'a>(
    file: &'a Path,
    text: &'a str,
) -> impl Iterator<Item = (Line<'a>, &'a str, SplitWhitespace<'a>)> {
    text.lines().enumerate().map(move |(i, line)| {
        let at = Line {
            file,
            number: i + 1,
        };
        (at, line, line.split_whitespace())
    })
}

struct Line<'a> {
    file: &'a Path,
    number: usize,
}

impl Line<'_> {
    fn syntax(&self, message: &str) -> SceneError {
        SceneError::Syntax {
            file: self.file.to_path_buf(),
            line: self.number,
            message: message.into(),
        }
    }

    /// Between `min` and `max` numbers (more are left in `words`), all finite.
    fn finite_numbers(
        &self,
        words: &mut SplitWhitespace,
        min: usize,
        max: usize,
    ) -> Result<Vec<f32>, SceneError> {
        let mut values = Vec::with_capacity(max);
        for w in words.by_ref().take(max) {
            let v: f32 = w
                .parse()
                .map_err(|_| self.syntax(&format!("'{w}' is not a number")))?;
            if !v.is_finite() {
                return Err(SceneError::NonFinite {
                    file: self.file.to_path_buf(),
                    line: self.number,
                });
            }
            values.push(v);
        }
        if values.len() < min {
            return Err(self.syntax(&format!("expected {min} numbers, found {}", values.len())));
        }
        Ok(values)
    }

    /// The statement's argument (a name that may contain spaces); it must not be empty.
    fn rest(&self, line: &str, keyword: &str) -> Result<String, SceneError> {
        let rest = line
            .trim_start()
            .strip_prefix(keyword)
            .unwrap_or_default()
            .trim();
        if rest.is_empty() {
            return Err(self.syntax(&format!("{keyword} needs a name")));
        }
        Ok(rest.to_owned())
    }

    /// `f v[/vt][/vn] ...` (or `l`): at least `min` corners, every index defined before this line.
    fn corners(
        &self,
        words: SplitWhitespace,
        defined: &Defined,
        min: usize,
    ) -> Result<(), SceneError> {
        let mut corners = 0;
        for corner in words {
            let mut parts = corner.split('/');
            let kinds = [
                ("vertex", defined.positions),
                ("texcoord", defined.texcoords),
                ("normal", defined.normals),
            ];
            for (k, (what, count)) in kinds.into_iter().enumerate() {
                match parts.next() {
                    Some("") if k > 0 => {}
                    Some(index) => self.index(index, what, count)?,
                    None => {}
                }
            }
            if parts.next().is_some() {
                return Err(self.syntax(&format!(
                    "face corner '{corner}' has more than three indices"
                )));
            }
            corners += 1;
        }
        if corners < min {
            return Err(self.syntax(&format!("needs at least {min} corners, found {corners}")));
        }
        Ok(())
    }

    fn index(&self, text: &str, what: &'static str, count: usize) -> Result<(), SceneError> {
        let index: i64 = text
            .parse()
            .map_err(|_| self.syntax(&format!("'{text}' is not a {what} index")))?;
        let resolved = if index < 0 {
            count as i64 + index
        } else {
            index - 1
        };
        if index == 0 || resolved < 0 || resolved >= count as i64 {
            return Err(SceneError::IndexOutOfRange {
                file: self.file.to_path_buf(),
                line: self.number,
                what,
                index,
                count,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj_error(text: &str) -> String {
        check_obj(Path::new("t.obj"), text)
            .expect_err("must be rejected")
            .to_string()
    }

    fn mtl_error(text: &str) -> String {
        check_mtl(Path::new("t.mtl"), text)
            .expect_err("must be rejected")
            .to_string()
    }

    const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

    #[test]
    fn accepts_ordinary_obj_and_collects_libraries() {
        let text = format!(
            "# c\nmtllib a b.mtl\n{TRIANGLE}vt 0 0\nvn 0 0 1\nusemtl red\nf 1/1/1 2/1/1 3/1/1\nf -3//1 -2//1 -1//1\nl 1 2\n"
        );
        let s = check_obj(Path::new("t.obj"), &text).expect("valid");
        assert_eq!(s.material_libraries, vec!["a b.mtl".to_string()]);
    }

    /// Each text is rejected by `error` with exactly its message.
    fn assert_rejected(error: impl Fn(&str) -> String, cases: &[(&str, &str)]) {
        for (text, message) in cases {
            assert_eq!(error(text), *message, "{text:?}");
        }
    }

    #[test]
    fn rejects_bad_obj_lines_naming_the_line() {
        assert_rejected(
            obj_error,
            &[
                (
                    "v 0 0 0\nv 1 nan 0\n",
                    "t.obj:2: non-finite number (NaN or infinity)",
                ),
                (
                    "v 0 0 inf\n",
                    "t.obj:1: non-finite number (NaN or infinity)",
                ),
                ("v 0 0\n", "t.obj:1: expected 3 numbers, found 2"),
                ("v 0 0 0 0\n", "t.obj:1: vertex weight w is zero"),
                ("v 0 x 0\n", "t.obj:1: 'x' is not a number"),
                ("usemtl\n", "t.obj:1: usemtl needs a name"),
                (
                    "v 0 0 0 1 1 1 1\n",
                    "t.obj:1: a vertex takes at most 6 numbers",
                ),
                ("vt 0\n", "t.obj:1: expected 2 numbers, found 1"),
            ],
        );
        // Lines after the three vertices of TRIANGLE.
        assert_rejected(
            |lines| obj_error(&format!("{TRIANGLE}{lines}")),
            &[
                (
                    "f 1 2 4\n",
                    "t.obj:4: vertex index 4 out of range (3 defined before this line)",
                ),
                (
                    "f 1 2 0\n",
                    "t.obj:4: vertex index 0 out of range (3 defined before this line)",
                ),
                (
                    "f -4 2 3\n",
                    "t.obj:4: vertex index -4 out of range (3 defined before this line)",
                ),
                (
                    "f 1//1 2//1 3//1\n",
                    "t.obj:4: normal index 1 out of range (0 defined before this line)",
                ),
                ("f 1 2\n", "t.obj:4: needs at least 3 corners, found 2"),
                (
                    "vt 0 0\nvn 0 0 1\nf 1 2 3/1/1/1\n",
                    "t.obj:6: face corner '3/1/1/1' has more than three indices",
                ),
                ("f 1 2 q\n", "t.obj:4: 'q' is not a vertex index"),
                (
                    "l 1 9\n",
                    "t.obj:4: vertex index 9 out of range (3 defined before this line)",
                ),
            ],
        );
    }

    #[test]
    fn rejects_bad_mtl_lines_naming_the_line() {
        assert_rejected(
            mtl_error,
            &[
                ("newmtl a\nKd 0.5\n", "t.mtl:2: expected 3 numbers, found 1"),
                (
                    "newmtl a\nKe 1 NaN 1\n",
                    "t.mtl:2: non-finite number (NaN or infinity)",
                ),
                ("newmtl a\nKd 1 -1 1\n", "t.mtl:2: negative colour"),
                (
                    "newmtl a\nillum x\n",
                    "t.mtl:2: illum needs an integer 0-255",
                ),
                ("newmtl\n", "t.mtl:1: newmtl needs a name"),
                ("newmtl a\nmap_Kd  \n", "t.mtl:2: map_Kd needs a name"),
                (
                    "newmtl a\nmap_Kd -clamp x.png\n",
                    "t.mtl:2: map_Kd option -clamp takes on or off",
                ),
                (
                    "newmtl a\nmap_Kd -s 2 2\n",
                    "t.mtl:2: map_Kd needs a file name after its options",
                ),
            ],
        );
        let names = check_mtl(
            Path::new("t.mtl"),
            "newmtl a\nKd 1 1 1\nNs 10\nillum 2\nmap_Kd x.png\nnewmtl b c\nmap_Kd -s 2 2 1 -bm 1 -clamp on my x.jpg\n",
        )
        .expect("valid");
        assert_eq!(names, ["a", "b c"]);
    }
}
