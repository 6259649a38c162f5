//! Line-oriented numeric text files (the label, marker and tracker-output files of NYU, Dexter-1
//! and the Handy layout): reading with the file named in errors, and parsing one line of
//! numbers with the file and line named.

use std::path::Path;

use crate::error::{DatasetError, Result};

/// The whole text of `path`; an unreadable file is an [`DatasetError::Io`] naming it.
pub fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| DatasetError::Io {
        file: path.to_path_buf(),
        source: e,
    })
}

/// A [`DatasetError::Parse`] at `line` (1-based) of `file`.
pub fn parse_error(file: &Path, line: Option<usize>, reason: impl Into<String>) -> DatasetError {
    DatasetError::Parse {
        file: file.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// The numbers of one line, separated by whitespace and/or commas (`x, y, z` or `x y z`).
/// Refused with the file and the 1-based line named: a token that is not a number, or a
/// non-finite value.
pub fn parse_numbers(line: &str, file: &Path, line_no: usize) -> Result<Vec<f64>> {
    line.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(parse_error(
                file,
                Some(line_no),
                format!("`{t}` is not a finite number"),
            )),
        })
        .collect()
}

/// The numbers of one line as `N` points `[x, y, z]`; refused when the line does not hold
/// exactly `3·N` numbers (a truncated line), with the file and line named.
pub fn parse_points<const N: usize>(
    line: &str,
    file: &Path,
    line_no: usize,
) -> Result<[[f64; 3]; N]> {
    let v = parse_numbers(line, file, line_no)?;
    if v.len() != 3 * N {
        return Err(parse_error(
            file,
            Some(line_no),
            format!(
                "expected {} numbers ({N} points × 3), found {}",
                3 * N,
                v.len()
            ),
        ));
    }
    let mut out = [[0.0; 3]; N];
    for (p, c) in out.iter_mut().zip(v.chunks_exact(3)) {
        p.copy_from_slice(c);
    }
    Ok(out)
}

/// Every non-empty line of `text` parsed by [`parse_points`], in order.
pub fn parse_point_rows<const N: usize>(text: &str, file: &Path) -> Result<Vec<[[f64; 3]; N]>> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| parse_points::<N>(l, file, i + 1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_points_and_errors_name_file_and_line() {
        let f = Path::new("f.txt");
        assert_eq!(
            parse_numbers("1, 2.5,-3  4e1", f, 1).unwrap(),
            vec![1.0, 2.5, -3.0, 40.0]
        );
        let e = parse_numbers("1 x 3", f, 7).unwrap_err().to_string();
        assert!(e.contains("f.txt, line 7") && e.contains("`x`"), "{e}");
        assert!(parse_numbers("nan", f, 1).is_err());
        assert_eq!(
            parse_points::<2>("1 2 3 4 5 6", f, 1).unwrap()[1],
            [4.0, 5.0, 6.0]
        );
        let e = parse_points::<2>("1 2 3 4 5", f, 3)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("expected 6 numbers"),
            "{e}"
        );
        let rows = parse_point_rows::<1>("1 2 3\n\n4 5 6\n", f).unwrap();
        assert_eq!(rows.len(), 2);
        let e = parse_point_rows::<1>("1 2 3\n\n4 5\n", f)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3"), "{e}");
        let e = read_text(Path::new("/nonexistent/x.txt")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.txt"));
    }
}
