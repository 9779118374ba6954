//! A Wavefront OBJ reader for triangle meshes: vertices and faces only (polygons are
//! triangulated as fans; normals and texture coordinates are ignored).

use crate::geometry::shape::Prim;
use crate::geometry::vec3::V3;

/// Parses OBJ text into triangles; `name` prefixes error messages with the line number.
pub fn parse(text: &str, name: &str) -> Result<Vec<Prim>, String> {
    let mut verts: Vec<V3> = Vec::new();
    let mut tris = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let err = |m: String| format!("{name}:{}: {m}", ln + 1);
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it
                    .take(3)
                    .map(|t| {
                        t.parse::<f32>()
                            .map_err(|_| err(format!("bad number '{t}'")))
                    })
                    .collect::<Result<_, _>>()?;
                if c.len() != 3 || c.iter().any(|v| !v.is_finite()) {
                    return Err(err("a vertex needs three finite coordinates".into()));
                }
                verts.push(V3(c[0], c[1], c[2]));
            }
            Some("f") => {
                let idx: Vec<usize> = it
                    .map(|t| {
                        let first = t.split('/').next().unwrap_or("");
                        let i: i64 = first
                            .parse()
                            .map_err(|_| err(format!("bad vertex index '{t}'")))?;
                        let n = verts.len() as i64;
                        let k = if i < 0 { n + i } else { i - 1 };
                        if k < 0 || k >= n {
                            return Err(err(format!(
                                "vertex index {i} out of range (1..={n} so far)"
                            )));
                        }
                        Ok(k as usize)
                    })
                    .collect::<Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(err("a face needs at least three vertices".into()));
                }
                for k in 1..idx.len() - 1 {
                    let (a, b, c) = (verts[idx[0]], verts[idx[k]], verts[idx[k + 1]]);
                    if (b - a).cross(c - a).len() > 0.0 {
                        tris.push(Prim::Triangle {
                            p0: a,
                            e1: b - a,
                            e2: c - a,
                        });
                    }
                }
            }
            _ => {} // vn, vt, g, o, s, usemtl, mtllib...: not needed
        }
    }
    if tris.is_empty() {
        return Err(format!("{name}: no faces"));
    }
    Ok(tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_quads_as_two_triangles_and_names_bad_lines() {
        let t = parse(
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/2 3 -1\n",
            "q.obj",
        )
        .unwrap();
        assert_eq!(t.len(), 2);
        let e = parse("v 0 0 0\nv 1 0 0\nf 1 2 7\n", "bad.obj").unwrap_err();
        assert!(e.starts_with("bad.obj:3:"), "{e}");
        let e = parse("v 0 0 x\n", "bad.obj").unwrap_err();
        assert!(e.starts_with("bad.obj:1:"), "{e}");
    }
}
