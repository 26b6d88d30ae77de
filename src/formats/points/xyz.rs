//! XYZ and CSV text points: one point per line, numbers separated by whitespace, commas or
//! semicolons, an optional header line naming the columns; read line by line, written exactly.
//!
//! The separator is the first content line's: a semicolon if it has one, else a comma if it
//! has one, else whitespace (tabs included). Lines starting with `#` and blank lines are
//! skipped. The first content line is a header when any of its fields is not a number: it
//! must name an x column (`x`, `easting`, `lon`, `longitude`) and a y column (`y`, `northing`,
//! `lat`, `latitude`), any case, optionally in double quotes; the first z column (`z`,
//! `elevation`, `height`, `h`) becomes the first value column and every other column a
//! further value column, in file order, each named by its header. Without a header a row is
//! `x y z [v2 v3 …]`: the value columns are named `z`, `v2`, `v3`, … (vK the K-th).
//!
//! Every row must have as many fields as the header (or the first row) and every field must
//! be a finite number; otherwise the read fails naming the line (`line 17: …`).

use crate::error::{Error, Result};
use crate::model::PointSet;
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// The longest line read (a guard against a file with no line breaks).
const MAX_LINE: usize = 1 << 20;

const X_NAMES: [&str; 4] = ["x", "easting", "lon", "longitude"];
const Y_NAMES: [&str; 4] = ["y", "northing", "lat", "latitude"];
const Z_NAMES: [&str; 4] = ["z", "elevation", "height", "h"];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Sep {
    Whitespace,
    Char(char),
}

impl Sep {
    fn of(line: &str) -> Sep {
        if line.contains(';') {
            Sep::Char(';')
        } else if line.contains(',') {
            Sep::Char(',')
        } else {
            Sep::Whitespace
        }
    }

    fn split<'a>(self, line: &'a str, out: &mut Vec<&'a str>) {
        out.clear();
        match self {
            Sep::Whitespace => out.extend(line.split_whitespace()),
            Sep::Char(c) => out.extend(line.split(c).map(str::trim)),
        }
    }
}

/// Where the columns of a row go.
struct Layout {
    fields: usize,
    x: usize,
    y: usize,
    /// The field of each value column, in the point set's order.
    values: Vec<usize>,
}

/// The default name of value column `c` (0-based) of a headerless file.
fn default_name(c: usize) -> String {
    if c == 0 {
        "z".into()
    } else {
        format!("v{}", c + 1)
    }
}

fn is_one_of(name: &str, names: &[&str]) -> bool {
    names.iter().any(|n| n.eq_ignore_ascii_case(name))
}

/// A header's column name without surrounding double quotes.
fn unquote(s: &str) -> &str {
    s.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(s)
}

fn layout_of_header(names: &[&str], line: u64) -> Result<(Layout, Vec<String>)> {
    let names: Vec<&str> = names.iter().map(|n| unquote(n)).collect();
    let find = |set: &[&str]| names.iter().position(|n| is_one_of(n, set));
    let Some(x) = find(&X_NAMES) else {
        return Err(Error::corrupt(format!(
            "line {line}: the header names no x column (one of {})",
            X_NAMES.join(", ")
        )));
    };
    let Some(y) = find(&Y_NAMES) else {
        return Err(Error::corrupt(format!(
            "line {line}: the header names no y column (one of {})",
            Y_NAMES.join(", ")
        )));
    };
    let z = find(&Z_NAMES);
    let mut values: Vec<usize> = z.into_iter().collect();
    values.extend((0..names.len()).filter(|&i| i != x && i != y && Some(i) != z));
    if values.is_empty() {
        return Err(Error::corrupt(format!(
            "line {line}: the header names no value column beside x and y"
        )));
    }
    if let Some(i) = values.iter().find(|&&i| names[i].is_empty()) {
        return Err(Error::corrupt(format!(
            "line {line}: column {} of the header has no name",
            i + 1
        )));
    }
    let out_names = values.iter().map(|&i| names[i].to_string()).collect();
    Ok((
        Layout {
            fields: names.len(),
            x,
            y,
            values,
        },
        out_names,
    ))
}

/// Parse one field of a row (1-based `column` for the message).
fn number(s: &str, line: u64, column: usize) -> Result<f64> {
    if s.is_empty() {
        return Err(Error::corrupt(format!(
            "line {line}: column {column} is empty"
        )));
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(Error::corrupt(format!(
            "line {line}: '{s}' in column {column} is not a finite number"
        ))),
        Err(_) => Err(Error::corrupt(format!(
            "line {line}: '{s}' in column {column} is not a number"
        ))),
    }
}

/// Read text points from `r`, line by line.
pub(super) fn read<R: BufRead>(mut r: R) -> Result<PointSet> {
    let mut ps = PointSet::default();
    let mut layout: Option<(Sep, Layout)> = None;
    let mut buf: Vec<u8> = Vec::new();
    let mut line_no: u64 = 0;
    loop {
        buf.clear();
        let n = Read::take(&mut r, MAX_LINE as u64 + 1)
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::io(format!("line {}", line_no + 1), e))?;
        if n == 0 {
            break;
        }
        line_no += 1;
        if buf.len() > MAX_LINE && buf.last() != Some(&b'\n') {
            return Err(Error::limit(format!(
                "line {line_no}: longer than {MAX_LINE} bytes"
            )));
        }
        let text = std::str::from_utf8(&buf)
            .map_err(|_| Error::corrupt(format!("line {line_no}: not UTF-8 text")))?;
        let text = if line_no == 1 {
            text.trim_start_matches('\u{feff}')
        } else {
            text
        };
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut fields: Vec<&str> = Vec::new();
        let (sep, lay) = match &layout {
            Some((sep, lay)) => (*sep, lay),
            None => {
                let sep = Sep::of(text);
                sep.split(text, &mut fields);
                let header = fields.iter().any(|f| f.parse::<f64>().is_err());
                let (lay, names) = if header {
                    layout_of_header(&fields, line_no)?
                } else if fields.len() < 3 {
                    return Err(Error::corrupt(format!(
                        "line {line_no}: {} fields; a point needs at least x, y and z",
                        fields.len()
                    )));
                } else {
                    let values: Vec<usize> = (2..fields.len()).collect();
                    let names = (0..values.len()).map(default_name).collect();
                    let lay = Layout {
                        fields: fields.len(),
                        x: 0,
                        y: 1,
                        values,
                    };
                    (lay, names)
                };
                ps.values = vec![Vec::new(); names.len()];
                ps.names = names;
                layout = Some((sep, lay));
                if header {
                    continue;
                }
                let (sep, lay) = layout.as_ref().expect("just set");
                (*sep, lay)
            }
        };
        sep.split(text, &mut fields);
        if fields.len() != lay.fields {
            return Err(Error::corrupt(format!(
                "line {line_no}: {} fields, expected {}",
                fields.len(),
                lay.fields
            )));
        }
        // Every field must be a number, even one no column keeps.
        let mut x = 0.0;
        let mut y = 0.0;
        for (i, f) in fields.iter().enumerate() {
            let v = number(f, line_no, i + 1)?;
            if i == lay.x {
                x = v;
            } else if i == lay.y {
                y = v;
            }
        }
        ps.x.push(x);
        ps.y.push(y);
        for (col, &i) in ps.values.iter_mut().zip(&lay.values) {
            col.push(fields[i].parse::<f64>().expect("checked above"));
        }
    }
    if layout.is_none() {
        // No header and no row: an empty set with the default column.
        ps.names = vec![default_name(0)];
        ps.values = vec![Vec::new()];
    }
    Ok(ps)
}

/// Refuse names a reader would not read back as the same column.
fn check_names(ps: &PointSet) -> Result<()> {
    for n in &ps.names {
        let bad = n.is_empty()
            || n.starts_with('#')
            || n.chars()
                .any(|c| c.is_whitespace() || c == ',' || c == ';' || c == '"')
            || n.parse::<f64>().is_ok()
            || is_one_of(n, &X_NAMES)
            || is_one_of(n, &Y_NAMES);
        if bad {
            return Err(Error::unsupported(format!(
                "value column name '{n}' cannot be written in a text header \
                 (empty, a number, an x or y name, or with a separator, quote or '#')"
            )));
        }
    }
    Ok(())
}

/// Write `ps` as text to `path` atomically: comma-separated with a header for CSV; otherwise
/// space-separated, with a header only when the names are not the defaults.
pub(super) fn write(path: &Path, ps: &PointSet, csv: bool, force: bool) -> Result<()> {
    let defaults = ps
        .names
        .iter()
        .enumerate()
        .all(|(c, n)| *n == default_name(c));
    let header = csv || !defaults;
    if header {
        check_names(ps)?;
    }
    let sep = if csv { "," } else { " " };
    let mut out = super::super::PendingFile::create(path, force)?;
    let ctx = format!("writing {}", path.display());
    let w = out.writer();
    let io = |e| Error::io(&ctx, e);
    if header {
        write!(w, "x{sep}y").map_err(io)?;
        for n in &ps.names {
            write!(w, "{sep}{n}").map_err(io)?;
        }
        writeln!(w).map_err(io)?;
    }
    for i in 0..ps.len() {
        // `{}` of an f64 is the shortest decimal that parses back to the same f64.
        write!(w, "{}{sep}{}", ps.x[i], ps.y[i]).map_err(io)?;
        for col in &ps.values {
            write!(w, "{sep}{}", col[i]).map_err(io)?;
        }
        writeln!(w).map_err(io)?;
    }
    out.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<PointSet> {
        read(s.as_bytes())
    }

    fn err(s: &str) -> String {
        parse(s).unwrap_err().to_string()
    }

    #[test]
    fn plain_rows_with_any_separator() {
        for text in [
            "1 2 3\n4 5 6\n",
            "1\t2  3\r\n 4 5\t6",
            "1,2,3\n4, 5 ,6\n",
            "1;2;3\n4;5;6\n",
        ] {
            let ps = parse(text).unwrap();
            assert_eq!(ps.x, [1.0, 4.0], "{text:?}");
            assert_eq!(ps.y, [2.0, 5.0]);
            assert_eq!(ps.names, ["z"]);
            assert_eq!(ps.values, [[3.0, 6.0]]);
        }
        let ps = parse("1 2 3 7 8\n").unwrap();
        assert_eq!(ps.names, ["z", "v2", "v3"]);
        assert_eq!(ps.values, [[3.0], [7.0], [8.0]]);
    }

    #[test]
    fn comments_blank_lines_and_a_byte_order_mark_are_skipped() {
        let ps = parse("\u{feff}# survey 2024\n\n  \n1 2 3\n# mid\n4 5 6\n\n").unwrap();
        assert_eq!(ps.len(), 2);
        let ps = parse("# only a comment\n").unwrap();
        assert!(ps.is_empty());
        assert_eq!(ps.names, ["z"]);
    }

    #[test]
    fn headers_name_the_columns() {
        let ps = parse("Easting,Northing,sigma,Elevation\n10,20,0.5,3\n").unwrap();
        assert_eq!(ps.x, [10.0]);
        assert_eq!(ps.y, [20.0]);
        // z first, then the others in file order, named by the header.
        assert_eq!(ps.names, ["Elevation", "sigma"]);
        assert_eq!(ps.values, [[3.0], [0.5]]);
        let ps = parse("\"lat\";\"lon\";\"h\"\n52;4;1.5\n").unwrap();
        assert_eq!((ps.x[0], ps.y[0], ps.values[0][0]), (4.0, 52.0, 1.5));
        assert_eq!(ps.names, ["h"]);
        // No z name: every other column is a value column.
        let ps = parse("x y depth\n1 2 -3\n").unwrap();
        assert_eq!(ps.names, ["depth"]);
        // A header with no x, y, or value column.
        assert!(err("a,b,c\n1,2,3\n").contains("line 1: the header names no x column"));
        assert!(err("# c\nx,z\n1,2\n").contains("line 2: the header names no y column"));
        assert!(err("x,y\n1,2\n").contains("no value column"));
    }

    #[test]
    fn bad_rows_name_their_line() {
        let e = err("x y z\n1 2 3\n# c\n4 5\n");
        assert!(e.contains("line 4: 2 fields, expected 3"), "{e}");
        let e = err("1 2 3\n1 2 3 4\n");
        assert!(e.contains("line 2: 4 fields, expected 3"), "{e}");
        let e = err("1 2 3\n4 5 NaN\n");
        assert!(
            e.contains("line 2: 'NaN' in column 3 is not a finite number"),
            "{e}"
        );
        let e = err("1 2 3\n4 inf 6\n");
        assert!(
            e.contains("line 2: 'inf' in column 2 is not a finite number"),
            "{e}"
        );
        let e = err("1,2,3\n4,5,six\n");
        assert!(
            e.contains("line 2: 'six' in column 3 is not a number"),
            "{e}"
        );
        let e = err("1,2,3\n4,,6\n");
        assert!(e.contains("line 2: column 2 is empty"), "{e}");
        let e = err("1 2\n");
        assert!(e.contains("line 1: 2 fields"), "{e}");
        // A NaN on the first row is data, not a header.
        let e = err("nan 2 3\n");
        assert!(e.contains("line 1: 'nan'"), "{e}");
        // A bad value is corrupt input (exit 1), not a usage error.
        assert!(matches!(
            parse("1 2 3\n4 5 x\n"),
            Err(Error::Corrupt { .. })
        ));
        let bytes: &[u8] = b"1 2 3\n4 5 \xff\n";
        let e = read(bytes).unwrap_err().to_string();
        assert!(e.contains("line 2: not UTF-8"), "{e}");
    }

    #[test]
    fn overlong_lines_are_a_limit() {
        let long = "1".repeat(MAX_LINE + 10);
        assert!(matches!(
            read(long.as_bytes()),
            Err(Error::LimitExceeded { .. })
        ));
    }

    #[test]
    fn numbers_parse_exactly() {
        let ps = parse("0.30000000000000004 446000.1 -0.1e-3\n").unwrap();
        assert_eq!(ps.x[0], 0.1 + 0.2);
        assert_eq!(ps.y[0], 446000.1_f64);
        assert_eq!(ps.values[0][0], -0.0001_f64);
    }

    fn awkward() -> PointSet {
        let x = vec![85_000.123_456_789, 0.1 + 0.2, -1e-300, 1e300, 5e-324];
        let y = vec![446000.1, 1.0 / 3.0, -0.0, 123456789.0, 2.0];
        let z = vec![-3.000000000000001, 7.0, 1e-7, f64::MAX, f64::MIN_POSITIVE];
        PointSet::from_xyz(x, y, z).unwrap()
    }

    #[test]
    fn text_round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let mut two = awkward();
        two.names = vec!["elevation".into(), "sigma".into()];
        two.values.push(vec![0.25, 0.5, 1.0, 2.0, 4.0]);
        let mut defaults = awkward();
        defaults.names.push("v2".into());
        defaults.values.push(vec![1.0, 2.0, 3.0, 4.0, 5.0]);
        for (i, ps) in [awkward(), two, defaults].iter().enumerate() {
            for csv in [false, true] {
                let p = dir
                    .path()
                    .join(format!("{i}.{}", if csv { "csv" } else { "xyz" }));
                write(&p, ps, csv, false).unwrap();
                let text = std::fs::read_to_string(&p).unwrap();
                assert_eq!(text.starts_with("x"), csv || i == 1, "{text}");
                let back = read(std::io::BufReader::new(std::fs::File::open(&p).unwrap()));
                let back = back.unwrap();
                assert_eq!(&back, ps, "{text}");
                for (a, b) in back.y.iter().zip(&ps.y) {
                    assert_eq!(a.to_bits(), b.to_bits());
                }
            }
        }
    }

    #[test]
    fn names_that_would_not_read_back_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a b", "x", "Lat", "12", "", "#z", "a,b"] {
            let mut ps = awkward();
            ps.names = vec![name.into()];
            let e = write(&dir.path().join("a.csv"), &ps, true, false).unwrap_err();
            assert!(matches!(e, Error::Unsupported { .. }), "{name}: {e}");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
