//! Writers for viewing results elsewhere: VTU (one time step of a volume mesh
//! with point and cell data), PVD (a time series of VTU files for ParaView),
//! OBJ and binary STL (surfaces).
//!
//! VTU arrays are written as inline base64 "binary" with UInt64 headers:
//! exact f64 values at a third of the size of ASCII, read by ParaView and by
//! our own reader. Writers check indices and array lengths before creating
//! the file, so a bad call leaves no half-written file behind.

use super::base64;
use super::error::MeshIoError;
use super::xml::escape;
use crate::ids::VertexId;
use crate::math::Vec3;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Creates `path` and runs `body` on a buffered writer, naming the file in
/// any I/O error.
pub(super) fn write_with(
    file: &str,
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), MeshIoError> {
    let io = |source| MeshIoError::Io {
        file: file.to_owned(),
        reason: source,
    };
    let mut w = BufWriter::new(File::create(path).map_err(io)?);
    body(&mut w).map_err(io)?;
    w.flush().map_err(io)
}

/// Checks that every index is below `count`.
pub(super) fn check_indices<'v>(
    file: &str,
    count: usize,
    indices: impl Iterator<Item = &'v VertexId>,
) -> Result<(), MeshIoError> {
    match indices.map(|v| v.idx()).find(|&v| v >= count) {
        Some(v) => Err(MeshIoError::BadInput {
            file: file.to_owned(),
            message: format!("vertex index {v} out of range: there are {count} positions"),
        }),
        None => Ok(()),
    }
}

/// One array of point or cell data: a value per point (or per cell).
#[derive(Clone, Copy, Debug)]
pub enum DataArray<'a> {
    /// 3-component vectors (Float64).
    Vectors(&'a [Vec3]),
    /// Scalars (Float64).
    Scalars(&'a [f64]),
    /// Integer ids (Int64 in VTU, `int` in legacy VTK), e.g. `original_id`.
    Ids(&'a [u32]),
}

impl DataArray<'_> {
    /// Number of values (points or cells).
    pub fn len(&self) -> usize {
        match self {
            DataArray::Vectors(v) => v.len(),
            DataArray::Scalars(v) => v.len(),
            DataArray::Ids(v) => v.len(),
        }
    }

    /// Whether it holds no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// VTK's type name, components and little-endian bytes.
    fn encoded(&self) -> (&'static str, usize, Vec<u8>) {
        match self {
            DataArray::Vectors(v) => ("Float64", 3, f64_bytes(v.iter().flat_map(|p| p.to_array()))),
            DataArray::Scalars(v) => ("Float64", 1, f64_bytes(v.iter().copied())),
            DataArray::Ids(v) => (
                "Int64",
                1,
                v.iter().flat_map(|&i| i64::from(i).to_le_bytes()).collect(),
            ),
        }
    }
}

/// Checks that each named array has `count` values (`what`: "point" or
/// "cell", `of`: what they are counted against).
pub(super) fn check_lengths(
    file: &str,
    what: &str,
    arrays: &[(&str, DataArray)],
    count: usize,
    of: &str,
) -> Result<(), MeshIoError> {
    match arrays.iter().find(|(_, a)| a.len() != count) {
        Some((name, a)) => Err(MeshIoError::BadInput {
            file: file.to_owned(),
            message: format!(
                "{what} data {name:?} has {} values for {count} {of}",
                a.len()
            ),
        }),
        None => Ok(()),
    }
}

/// One base64 DataArray: uncompressed, a UInt64 byte count then the
/// bytes, one stream; compressed (`zlib`), VTK's block header and the
/// blocks, two streams.
fn data_array(
    w: &mut impl Write,
    ty: &str,
    name: &str,
    components: usize,
    payload: &[u8],
    zlib: bool,
) -> std::io::Result<()> {
    // One component is VTK's default: saying it makes meshio read an (n, 1)
    // array where the file holds one value per point or cell.
    let components = if components == 1 {
        String::new()
    } else {
        format!(" NumberOfComponents=\"{components}\"")
    };
    writeln!(
        w,
        "        <DataArray type=\"{ty}\" Name=\"{}\"{components} format=\"binary\">",
        escape(name)
    )?;
    if zlib {
        let (header, blocks) =
            super::vtk_zlib::deflate_array(payload, super::vtk_zlib::WRITE_BLOCK, 8);
        writeln!(
            w,
            "          {}{}",
            base64::encode(&header),
            base64::encode(&blocks)
        )?;
    } else {
        let mut raw = Vec::with_capacity(8 + payload.len());
        raw.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        raw.extend_from_slice(payload);
        writeln!(w, "          {}", base64::encode(&raw))?;
    }
    writeln!(w, "        </DataArray>")
}

fn f64_bytes(values: impl Iterator<Item = f64>) -> Vec<u8> {
    values.flat_map(f64::to_le_bytes).collect()
}

/// Writes a VTU file: linear tetrahedra with `point_data` (one value per
/// position) and `cell_data` (one per tetrahedron), uncompressed.
pub fn write_vtu(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    point_data: &[(&str, DataArray)],
    cell_data: &[(&str, DataArray)],
) -> Result<(), MeshIoError> {
    vtu(path, positions_m, tets, point_data, cell_data, false)
}

/// [`write_vtu`] with every array zlib-compressed
/// (`vtkZLibDataCompressor`, what ParaView writes): about a third of the
/// size for a simulation frame, at a few milliseconds of compression.
pub fn write_vtu_zlib(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    point_data: &[(&str, DataArray)],
    cell_data: &[(&str, DataArray)],
) -> Result<(), MeshIoError> {
    vtu(path, positions_m, tets, point_data, cell_data, true)
}

fn vtu(
    path: &Path,
    positions_m: &[Vec3],
    tets: &[[VertexId; 4]],
    point_data: &[(&str, DataArray)],
    cell_data: &[(&str, DataArray)],
    zlib: bool,
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    check_indices(&file, positions_m.len(), tets.iter().flatten())?;
    check_lengths(&file, "point", point_data, positions_m.len(), "points")?;
    check_lengths(&file, "cell", cell_data, tets.len(), "tetrahedra")?;
    write_with(&file, path, |w| {
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(
            w,
            "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"{}>",
            if zlib {
                " compressor=\"vtkZLibDataCompressor\""
            } else {
                ""
            }
        )?;
        writeln!(w, "  <UnstructuredGrid>")?;
        writeln!(
            w,
            "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
            positions_m.len(),
            tets.len()
        )?;
        writeln!(w, "      <Points>")?;
        let (ty, comps, bytes) = DataArray::Vectors(positions_m).encoded();
        data_array(w, ty, "Points", comps, &bytes, zlib)?;
        writeln!(w, "      </Points>")?;
        writeln!(w, "      <Cells>")?;
        let conn: Vec<u8> = tets
            .iter()
            .flatten()
            .flat_map(|v| i64::from(v.0).to_le_bytes())
            .collect();
        data_array(w, "Int64", "connectivity", 1, &conn, zlib)?;
        let offsets: Vec<u8> = (1..=tets.len() as i64)
            .flat_map(|c| (4 * c).to_le_bytes())
            .collect();
        data_array(w, "Int64", "offsets", 1, &offsets, zlib)?;
        data_array(w, "UInt8", "types", 1, &vec![10u8; tets.len()], zlib)?;
        writeln!(w, "      </Cells>")?;
        for (section, arrays) in [("PointData", point_data), ("CellData", cell_data)] {
            writeln!(w, "      <{section}>")?;
            for (name, values) in arrays {
                let (ty, comps, bytes) = values.encoded();
                data_array(w, ty, name, comps, &bytes, zlib)?;
            }
            writeln!(w, "      </{section}>")?;
        }
        writeln!(w, "    </Piece>")?;
        writeln!(w, "  </UnstructuredGrid>")?;
        writeln!(w, "</VTKFile>")
    })
}

/// Writes a PVD collection: one `DataSet` per step with its time (s). Each
/// VTU path is written relative to the PVD's directory: a path inside that
/// directory loses the directory prefix, any other is written as given
/// (ParaView resolves relative paths from the PVD's directory). Written
/// beside it and renamed into place: a run rewriting its series is never
/// seen (or killed) with half a file.
pub fn write_pvd(path: &Path, steps: &[(f64, PathBuf)]) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    if let Some((t, p)) = steps.iter().find(|(t, _)| !t.is_finite()) {
        return Err(MeshIoError::BadInput {
            file,
            message: format!("time {t} of {} is not finite", p.display()),
        });
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    write_with(&file, &tmp, |w| {
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(
            w,
            "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">"
        )?;
        writeln!(w, "  <Collection>")?;
        for (t, vtu) in steps {
            let rel = match vtu.strip_prefix(dir) {
                Ok(r) if !dir.as_os_str().is_empty() => r,
                _ => vtu.as_path(),
            };
            // Forward slashes: ParaView on any platform reads them.
            let rel = rel.to_string_lossy().replace('\\', "/");
            writeln!(
                w,
                "    <DataSet timestep=\"{t:e}\" group=\"\" part=\"0\" file=\"{}\"/>",
                escape(&rel)
            )?;
        }
        writeln!(w, "  </Collection>")?;
        writeln!(w, "</VTKFile>")
    })?;
    std::fs::rename(&tmp, path).map_err(|source| MeshIoError::Io {
        file,
        reason: source,
    })
}

/// Writes a Wavefront OBJ surface (vertices and 1-based triangle faces).
pub fn write_obj(
    path: &Path,
    positions_m: &[Vec3],
    triangles: &[[VertexId; 3]],
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    check_indices(&file, positions_m.len(), triangles.iter().flatten())?;
    write_with(&file, path, |w| {
        writeln!(
            w,
            "# {} vertices, {} triangles, metres",
            positions_m.len(),
            triangles.len()
        )?;
        for p in positions_m {
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        for t in triangles {
            writeln!(w, "f {} {} {}", t[0].0 + 1, t[1].0 + 1, t[2].0 + 1)?;
        }
        Ok(())
    })
}

/// Writes a binary STL: an 80-byte header, the triangle count, then per
/// triangle its unit normal (from the winding; zero if degenerate), its three
/// corners (f32, metres) and a zero attribute: 84 + 50 n bytes.
pub fn write_stl(
    path: &Path,
    positions_m: &[Vec3],
    triangles: &[[VertexId; 3]],
) -> Result<(), MeshIoError> {
    let file = path.display().to_string();
    check_indices(&file, positions_m.len(), triangles.iter().flatten())?;
    let count = u32::try_from(triangles.len()).map_err(|_| MeshIoError::BadInput {
        file: file.clone(),
        message: format!("{} triangles do not fit a binary STL", triangles.len()),
    })?;
    write_with(&file, path, |w| {
        let mut header = [b' '; 80];
        let text = b"binary STL from sim-server, metres";
        header[..text.len()].copy_from_slice(text);
        w.write_all(&header)?;
        w.write_all(&count.to_le_bytes())?;
        for t in triangles {
            let [a, b, c] = t.map(|v| positions_m[v.idx()]);
            let n = (b - a).cross(c - a).normalize_or_zero();
            for v in [n, a, b, c] {
                for x in v.to_array() {
                    w.write_all(&(x as f32).to_le_bytes())?;
                }
            }
            w.write_all(&[0, 0])?;
        }
        Ok(())
    })
}
