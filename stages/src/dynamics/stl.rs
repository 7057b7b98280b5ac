//! The bounding box of an STL mesh (binary or ASCII), and where a URDF's
//! mesh file is: what the physical fit needs of a link's shape.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::model::Extent;
use crate::{Error, Result};

/// The file a URDF's `<mesh filename>` names, when it is an STL found on
/// disk: `package://pkg/rest` looked up as `pkg/rest` or `rest` in the
/// URDF's folder and those above it (where a ROS workspace keeps its
/// packages), `file://` absolute, anything else relative to the URDF.
pub fn resolve(filename: &str, urdf: &Path) -> Option<PathBuf> {
    let is_stl = |p: &Path| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("stl")) && p.is_file();
    let dir = urdf.parent().unwrap_or(Path::new("."));
    if let Some(rest) = filename.strip_prefix("package://") {
        let tail = rest.split_once('/').map_or(rest, |(_, t)| t);
        return dir
            .ancestors()
            .flat_map(|a| [a.join(rest), a.join(tail)])
            .find(|p| is_stl(p));
    }
    let p = match filename.strip_prefix("file://") {
        Some(abs) => PathBuf::from(abs),
        None => dir.join(filename),
    };
    is_stl(&p).then_some(p)
}

/// The box holding an STL file's vertices, in its units.
pub fn extent(path: &Path) -> Result<Extent> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |why: &str| Error::Format {
        path: path.to_path_buf(),
        msg: format!("not an STL mesh: {why}"),
    };
    // Binary: an 80-byte header, a triangle count, 50 bytes per triangle.
    let binary = bytes.len() >= 84 && {
        let n = u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as usize;
        n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len())
    };
    let points: Vec<Vector3<f64>> = if binary {
        bytes[84..]
            .chunks_exact(50)
            .flat_map(|t| {
                (0..3).map(move |v| {
                    let f = |k: usize| {
                        let at = 12 + 12 * v + 4 * k;
                        f32::from_le_bytes(t[at..at + 4].try_into().expect("4 bytes")) as f64
                    };
                    Vector3::new(f(0), f(1), f(2))
                })
            })
            .collect()
    } else {
        let text = std::str::from_utf8(&bytes).map_err(|_| bad("neither binary nor text"))?;
        text.lines()
            .filter_map(|l| l.trim().strip_prefix("vertex"))
            .map(|v| {
                let x: Vec<f64> = v.split_whitespace().filter_map(|x| x.parse().ok()).collect();
                match x[..] {
                    [a, b, c] => Ok(Vector3::new(a, b, c)),
                    _ => Err(bad(&format!("vertex `{}`", v.trim()))),
                }
            })
            .collect::<Result<_>>()?
    };
    if let Some(p) = points.iter().find(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(bad(&format!("vertex {p:?} is not finite")));
    }
    Extent::of_points(points).ok_or_else(|| bad("no vertex"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's corners, written both ways, give the same box.
    #[test]
    fn binary_and_ascii_meshes_give_their_box() {
        let dir = tempfile::tempdir().unwrap();
        let tri = [[0.0f32, 0.0, -1.0], [2.0, 0.5, 0.0], [0.0, 3.0, 4.0]];
        let mut bin = vec![0u8; 80];
        bin.extend(1u32.to_le_bytes());
        bin.extend([0u8; 12]);
        for v in tri {
            for x in v {
                bin.extend(x.to_le_bytes());
            }
        }
        bin.extend([0u8; 2]);
        let b = dir.path().join("m.stl");
        std::fs::write(&b, &bin).unwrap();
        let a = dir.path().join("a.STL");
        std::fs::write(
            &a,
            "solid m\nfacet normal 0 0 1\nouter loop\nvertex 0 0 -1\nvertex 2 0.5 0\nvertex 0 3 4\nendloop\nendfacet\nendsolid m\n",
        )
        .unwrap();
        for p in [&b, &a] {
            let e = extent(p).unwrap();
            assert_eq!(e.min, Vector3::new(0.0, 0.0, -1.0));
            assert_eq!(e.max, Vector3::new(2.0, 3.0, 4.0));
        }
        let urdf = dir.path().join("robot.urdf");
        assert_eq!(resolve("package://desc/a.STL", &urdf), Some(a.clone()));
        assert_eq!(resolve("m.stl", &urdf), Some(b));
        assert_eq!(resolve("package://desc/missing.stl", &urdf), None);
        std::fs::write(dir.path().join("x.stl"), "solid\nvertex 1 nope 2\n").unwrap();
        assert!(extent(&dir.path().join("x.stl"))
            .unwrap_err()
            .to_string()
            .contains("vertex"));
    }
}
