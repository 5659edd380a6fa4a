//! Vessel centrelines from files: CSV of points (3D Slicer's markups
//! `.fcsv` included) and legacy VTK polydata with `LINES` (VMTK's and
//! Slicer's centreline models saved as `.vtk`). Each file gives one or more
//! polylines; faults are named by file and line.

use crate::math::Vec3;
use std::path::Path;

/// The most points a centreline file may hold (a 1 m vessel at 0.01 mm).
pub const MAX_POINTS: usize = 100_000;

/// Reads `path` by its extension: `.csv`, `.fcsv`, `.txt` (one point per
/// line) or `.vtk` (polylines). Coordinates as in the file.
pub fn read_polylines(path: &Path) -> Result<Vec<Vec<Vec3>>, String> {
    let name = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let bytes = std::fs::read(path).map_err(|e| format!("{name}: {e}"))?;
    if bytes.len() > 64 << 20 {
        return Err(format!("{name}: larger than 64 MB: not a centreline"));
    }
    let text = String::from_utf8_lossy(&bytes);
    match ext.as_deref() {
        Some("csv" | "fcsv" | "txt") => csv_points(&name, &text).map(|p| vec![p]),
        Some("vtk") => vtk_lines(&name, &text),
        _ => Err(format!(
            "{name}: a centreline is a CSV of points (.csv, .fcsv, .txt) or a legacy VTK polyline (.vtk)"
        )),
    }
}

/// One point per line: the columns named x, y, z by a header (Slicer's
/// `# columns = id,x,y,z,...` counts), else the first three numbers.
/// Lines starting with `#` are comments; separators are commas,
/// semicolons, tabs or spaces.
fn csv_points(name: &str, text: &str) -> Result<Vec<Vec3>, String> {
    let split = |l: &str| -> Vec<String> {
        l.split([',', ';', '\t', ' '])
            .map(|f| f.trim().to_ascii_lowercase())
            .filter(|f| !f.is_empty())
            .collect()
    };
    let mut columns: Option<[usize; 3]> = None;
    let mut points = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = i + 1;
        let line = line.trim();
        let header = |fields: &[String]| {
            let find = |k: &str| fields.iter().position(|f| f == k);
            match (find("x"), find("y"), find("z")) {
                (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                _ => None,
            }
        };
        if let Some(rest) = line.strip_prefix('#') {
            if let Some(cols) = rest.trim().strip_prefix("columns =") {
                columns = header(&split(cols));
            }
            continue;
        }
        if line.is_empty() {
            continue;
        }
        let fields = split(line);
        if points.is_empty()
            && columns.is_none()
            && fields.iter().any(|f| f.parse::<f64>().is_err())
        {
            columns = header(&fields);
            if columns.is_none() {
                return Err(format!(
                    "{name}:{at}: a header must name the columns x, y and z"
                ));
            }
            continue;
        }
        let [cx, cy, cz] = columns.unwrap_or([0, 1, 2]);
        let value = |c: usize, axis: &str| -> Result<f64, String> {
            let f = fields
                .get(c)
                .ok_or_else(|| format!("{name}:{at}: no {axis} value (column {})", c + 1))?;
            f.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{name}:{at}: {axis} = {f:?} is not a finite number"))
        };
        points.push(Vec3::new(value(cx, "x")?, value(cy, "y")?, value(cz, "z")?));
        if points.len() > MAX_POINTS {
            return Err(format!("{name}: more than {MAX_POINTS} points"));
        }
    }
    if points.len() < 2 {
        return Err(format!("{name}: a centreline needs at least two points"));
    }
    Ok(points)
}

/// Legacy ASCII VTK polydata: `POINTS n type`, then `LINES n size` with
/// each line `k i0 .. ik-1`.
fn vtk_lines(name: &str, text: &str) -> Result<Vec<Vec<Vec3>>, String> {
    if text
        .lines()
        .nth(2)
        .is_some_and(|l| l.trim().eq_ignore_ascii_case("BINARY"))
    {
        return Err(format!(
            "{name}:3: binary VTK: save the centreline as ASCII"
        ));
    }
    // Tokens with their line numbers.
    let tokens: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .skip(3)
        .flat_map(|(i, l)| l.split_whitespace().map(move |t| (i + 1, t)))
        .collect();
    let mut tokens = tokens.into_iter();
    let mut next = |what: &str| -> Result<(usize, &str), String> {
        tokens
            .next()
            .ok_or_else(|| format!("{name}: the file ends inside {what}"))
    };
    let mut points: Vec<Vec3> = Vec::new();
    let mut lines = Vec::new();
    let count = |(at, t): (usize, &str), what: &str, max: usize| -> Result<usize, String> {
        t.parse::<usize>()
            .ok()
            .filter(|n| *n <= max)
            .ok_or_else(|| format!("{name}:{at}: {what} {t:?} is not a count up to {max}"))
    };
    while let Ok((at, word)) = next("a section") {
        match word.to_ascii_uppercase().as_str() {
            "POINTS" => {
                let n = count(next("POINTS")?, "POINTS", MAX_POINTS)?;
                next("POINTS")?;
                points.clear();
                for _ in 0..n {
                    let mut c = [0.0; 3];
                    for v in &mut c {
                        let (at, t) = next("POINTS")?;
                        *v = t
                            .parse::<f64>()
                            .ok()
                            .filter(|v| v.is_finite())
                            .ok_or_else(|| {
                                format!("{name}:{at}: {t:?} is not a finite coordinate")
                            })?;
                    }
                    points.push(Vec3::from_array(c));
                }
            }
            "LINES" => {
                let n = count(next("LINES")?, "LINES", MAX_POINTS)?;
                next("LINES")?;
                for _ in 0..n {
                    let m = count(next("LINES")?, "a line's point count", MAX_POINTS)?;
                    let mut line = Vec::with_capacity(m);
                    for _ in 0..m {
                        let (at, t) = next("LINES")?;
                        let i = t
                            .parse::<usize>()
                            .ok()
                            .filter(|i| *i < points.len())
                            .ok_or_else(|| {
                                format!(
                                    "{name}:{at}: point {t:?} is not one of the {} POINTS",
                                    points.len()
                                )
                            })?;
                        line.push(points[i]);
                    }
                    if line.len() >= 2 {
                        lines.push(line);
                    }
                }
            }
            "DATASET" => {
                let (at, kind) = next("DATASET")?;
                if !kind.eq_ignore_ascii_case("POLYDATA") {
                    return Err(format!(
                        "{name}:{at}: DATASET {kind}: a centreline is POLYDATA with LINES"
                    ));
                }
            }
            "POINT_DATA" | "CELL_DATA" | "FIELD" => break,
            _ => {
                return Err(format!(
                    "{name}:{at}: unexpected {word:?} (a centreline has POINTS and LINES)"
                ));
            }
        }
    }
    if lines.is_empty() {
        return Err(format!("{name}: no LINES with two points or more"));
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slicer_markups_and_plain_csv_give_the_same_points() {
        let fcsv = "# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\nvtkMRML_1,10,20,30,0,0,0,1,1,1,0,F-1,,\nvtkMRML_2,11.5,20,31,0,0,0,1,1,1,0,F-2,,\n";
        let plain = "x,y,z\n10,20,30\n11.5,20,31\n";
        let bare = "10 20 30\n11.5 20 31\n";
        let a = csv_points("a", fcsv).unwrap();
        assert_eq!(
            a,
            vec![Vec3::new(10.0, 20.0, 30.0), Vec3::new(11.5, 20.0, 31.0)]
        );
        assert_eq!(csv_points("b", plain).unwrap(), a);
        assert_eq!(csv_points("c", bare).unwrap(), a);
        let e = csv_points("v.csv", "x,y,z\n1,2,3\n1,zwei,3\n").unwrap_err();
        assert!(e.contains("v.csv:3") && e.contains("zwei"), "{e}");
        let e = csv_points("v.csv", "a,b,c\n1,2,3\n").unwrap_err();
        assert!(e.contains("v.csv:1"), "{e}");
    }

    #[test]
    fn vtk_polylines_are_read_with_their_faults_located() {
        let vtk = "# vtk DataFile Version 3.0\ncentreline\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0\n2 0 0 2 1 0\nLINES 2 7\n3 0 1 2\n2 2 3\nPOINT_DATA 4\n";
        let l = vtk_lines("c.vtk", vtk).unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].len(), 3);
        assert_eq!(l[1][1], Vec3::new(2.0, 1.0, 0.0));
        let bad = vtk.replace("2 2 3", "2 2 9");
        let e = vtk_lines("c.vtk", &bad).unwrap_err();
        assert!(e.contains("c.vtk:10") && e.contains("\"9\""), "{e}");
        let e = vtk_lines(
            "c.vtk",
            "# vtk\nx\nASCII\nDATASET POLYDATA\nPOINTS 99999999999 float\n",
        )
        .unwrap_err();
        assert!(e.contains("c.vtk:5"), "{e}");
    }
}
