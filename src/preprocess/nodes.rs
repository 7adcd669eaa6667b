//! Nodes of the global response: the render mesh's (welded) vertices, or those of a simplified
//! proxy mesh when the render mesh is finer than the material needs.
//!
//! Each render vertex is tied to the nodes by weights that sum to 1 (its prolongation): itself
//! when it is a node, else the barycentric weights of its closest point on the proxy mesh
//! (only proxy triangles facing the same way are considered, so that the two sides of a thin
//! part are not mixed). The node basis function phi_p is the linear interpolation of these
//! weights over the render triangles: the composite interpolates B across render triangles, so
//! every operator uses that same phi_p.

use crate::scene::mesh::Mesh;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// The node set and the map from render vertices to nodes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Nodes {
    /// Node positions, mm.
    pub positions: Vec<Vec3>,
    /// Node normals.
    pub normals: Vec<Vec3>,
    /// Per render vertex: (node, weight) pairs, weights summing to 1.
    pub prolong: Vec<Vec<(u32, f32)>>,
    /// Whether the render mesh was simplified.
    pub simplified: bool,
    /// Mean edge length of the node mesh, mm.
    pub spacing_mm: f64,
}

fn mean_edge(positions: &[Vec3], indices: &[u32]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for t in indices.chunks(3) {
        for k in 0..3 {
            sum += positions[t[k] as usize].distance(positions[t[(k + 1) % 3] as usize]) as f64;
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// Closest point of triangle (a, b, c) to p, as barycentric weights (Ericson, Real-Time
/// Collision Detection, 5.1.5).
fn closest_barycentric(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

/// The render mesh welded by position: per render vertex its welded vertex, and the welded
/// mesh's positions and indices.
struct Welded {
    of: Vec<u32>,
    positions: Vec<Vec3>,
    indices: Vec<u32>,
}

impl Welded {
    /// Welds `mesh` by position, so that seams of normals or texture coordinates do not split
    /// nodes.
    fn new(mesh: &Mesh) -> Welded {
        let weld = mesh.welded();
        let mut compact = vec![u32::MAX; mesh.positions.len()];
        let mut welded_of = Vec::with_capacity(mesh.positions.len());
        let mut first = Vec::new();
        for (i, &w) in weld.iter().enumerate() {
            if compact[w as usize] == u32::MAX {
                compact[w as usize] = first.len() as u32;
                first.push(i as u32);
            }
            welded_of.push(compact[w as usize]);
        }
        let welded_positions: Vec<Vec3> =
            first.iter().map(|&i| mesh.positions[i as usize]).collect();
        let welded_indices: Vec<u32> = mesh
            .indices
            .iter()
            .map(|&i| welded_of[i as usize])
            .collect();
        Welded {
            of: welded_of,
            positions: welded_positions,
            indices: welded_indices,
        }
    }

    /// The normals of welded vertices `ids`: the normalised sum of their render vertices'
    /// normals.
    fn normals(&self, mesh: &Mesh, ids: &[u32]) -> Vec<Vec3> {
        let mut acc = vec![Vec3::ZERO; self.positions.len()];
        for (v, &w) in self.of.iter().enumerate() {
            acc[w as usize] += mesh.normals[v];
        }
        ids.iter()
            .map(|&w| acc[w as usize].normalize_or_zero())
            .collect()
    }
}

/// The simplified proxy mesh: node ids of the welded vertices it keeps, each node's welded
/// vertex and position, its triangles in node ids, and its mean edge.
struct Proxy {
    node_of: HashMap<u32, u32>,
    node_welded: Vec<u32>,
    positions: Vec<Vec3>,
    tris: Vec<[u32; 3]>,
    spacing: f64,
}

impl Proxy {
    /// Simplifies the welded mesh to about `ratio`^2 of its triangles.
    fn new(welded: &Welded, ratio: f64) -> Proxy {
        let welded_positions = &welded.positions;
        let welded_indices = &welded.indices;
        let target_indices =
            ((welded_indices.len() as f64) * ratio * ratio).max(12.0) as usize / 3 * 3;
        let adapter =
            meshopt::VertexDataAdapter::new(bytemuck::cast_slice(welded_positions), 12, 0)
                .expect("positions are 12-byte vertices");
        let simplified = meshopt::simplify(
            welded_indices,
            &adapter,
            target_indices,
            1.0,
            // Even triangle sizes: flat regions would otherwise collapse into a few large
            // triangles, and the global response needs nodes spread at the spacing asked for.
            meshopt::SimplifyOptions::Regularize,
            None,
        );
        // Node ids for the welded vertices the proxy keeps.
        let mut node_of: HashMap<u32, u32> = HashMap::new();
        let mut node_welded = Vec::new();
        for &w in &simplified {
            node_of.entry(w).or_insert_with(|| {
                node_welded.push(w);
                (node_welded.len() - 1) as u32
            });
        }
        let positions: Vec<Vec3> = node_welded
            .iter()
            .map(|&w| welded_positions[w as usize])
            .collect();
        let tris: Vec<[u32; 3]> = simplified
            .chunks(3)
            .map(|t| [node_of[&t[0]], node_of[&t[1]], node_of[&t[2]]])
            .collect();
        let node_spacing = mean_edge(welded_positions, &simplified);
        Proxy {
            node_of,
            node_welded,
            positions,
            tris,
            spacing: node_spacing,
        }
    }
}

/// A cell of the proxy's grid.
type Cell = (i64, i64, i64);

/// Uniform grid of proxy triangles for closest-point queries (cells two node spacings wide),
/// with the triangles' normals.
struct Grid {
    cell: f64,
    cells: HashMap<Cell, Vec<u32>>,
    tri_normals: Vec<DVec3>,
}

impl Grid {
    /// The grid of `proxy`'s triangles.
    fn new(proxy: &Proxy) -> Grid {
        let (positions, tris) = (&proxy.positions, &proxy.tris);
        let mut grid = Grid {
            cell: (2.0 * proxy.spacing).max(1e-6),
            cells: HashMap::new(),
            tri_normals: Vec::new(),
        };
        for (ti, t) in tris.iter().enumerate() {
            let ps = t.map(|n| positions[n as usize].as_dvec3());
            let (lo, hi) = (
                grid.key(ps[0].min(ps[1]).min(ps[2])),
                grid.key(ps[0].max(ps[1]).max(ps[2])),
            );
            for x in lo.0..=hi.0 {
                for y in lo.1..=hi.1 {
                    for z in lo.2..=hi.2 {
                        grid.cells.entry((x, y, z)).or_default().push(ti as u32);
                    }
                }
            }
        }
        grid.tri_normals = tris
            .iter()
            .map(|t| {
                let ps = t.map(|n| positions[n as usize].as_dvec3());
                (ps[1] - ps[0]).cross(ps[2] - ps[0]).normalize_or_zero()
            })
            .collect();
        grid
    }

    /// The cell that holds `p`.
    fn key(&self, p: DVec3) -> Cell {
        let cell = self.cell;
        (
            (p.x / cell).floor() as i64,
            (p.y / cell).floor() as i64,
            (p.z / cell).floor() as i64,
        )
    }

    /// The closest point to `p` on the proxy triangles facing the way of `pn` (the cosine
    /// between the normals at least 0.2) in the cells around `p`, one ring of cells further at
    /// a time up to four: (squared distance, triangle, barycentric weights).
    fn closest_facing(&self, proxy: &Proxy, p: DVec3, pn: DVec3) -> Option<(f64, u32, [f64; 3])> {
        let (positions, tris) = (&proxy.positions, &proxy.tris);
        let c = self.key(p);
        let mut best: Option<(f64, u32, [f64; 3])> = None;
        for reach in 1..=4i64 {
            for x in c.0 - reach..=c.0 + reach {
                for y in c.1 - reach..=c.1 + reach {
                    for z in c.2 - reach..=c.2 + reach {
                        for &ti in self.cells.get(&(x, y, z)).into_iter().flatten() {
                            if self.tri_normals[ti as usize].dot(pn) < 0.2 {
                                continue;
                            }
                            let ps = tris[ti as usize].map(|n| positions[n as usize].as_dvec3());
                            let b = closest_barycentric(p, ps[0], ps[1], ps[2]);
                            let q = ps[0] * b[0] + ps[1] * b[1] + ps[2] * b[2];
                            let d = q.distance_squared(p);
                            if best.is_none_or(|(bd, _, _)| d < bd) {
                                best = Some((d, ti, b));
                            }
                        }
                    }
                }
            }
            if best.is_some() {
                break;
            }
        }
        best
    }
}

/// The prolongation of welded vertex `w` (normal `welded_normals[w]`): itself where it is a
/// node, else the barycentric weights of its closest point on a facing proxy triangle nearby,
/// else the nearest node.
fn welded_weights(
    w: usize,
    welded: &Welded,
    welded_normals: &[Vec3],
    proxy: &Proxy,
    grid: &Grid,
) -> Vec<(u32, f32)> {
    let (positions, tris) = (&proxy.positions, &proxy.tris);
    if let Some(&n) = proxy.node_of.get(&(w as u32)) {
        return vec![(n, 1.0)];
    }
    let p = welded.positions[w].as_dvec3();
    let pn = welded_normals[w].as_dvec3();
    match grid.closest_facing(proxy, p, pn) {
        Some((_, ti, b)) => tris[ti as usize]
            .iter()
            .zip(b)
            .filter(|(_, w)| *w > 1e-6)
            .map(|(n, w)| (*n, w as f32))
            .collect(),
        None => {
            // No facing proxy triangle nearby: tie to the nearest node.
            let nearest = positions
                .iter()
                .enumerate()
                .min_by(|a, b| {
                    a.1.distance_squared(p.as_vec3())
                        .total_cmp(&b.1.distance_squared(p.as_vec3()))
                })
                .map(|(i, _)| i as u32)
                .unwrap_or(0);
            vec![(nearest, 1.0)]
        }
    }
}

impl Nodes {
    /// Builds the nodes for `mesh` with a target spacing (mm).
    pub fn build(mesh: &Mesh, spacing_mm: f64) -> Nodes {
        // Weld by position so that seams of normals or texture coordinates do not split nodes.
        let welded = Welded::new(mesh);
        // The mesh's resolution: its mean edge, or the spacing its vertex count implies
        // (area per vertex 0.866 e^2 on an even mesh), whichever is finer. A mesh of long
        // polygons (a 2000-gon disc, a 1000-segment cylinder) has long edges across and
        // vertices crowded along them: by the mean edge alone it is "coarse enough", and every
        // one of its 1000-2000 vertices would become a node (F nearly dense, a long fit).
        let density = (mesh.surface_area() / (0.866 * welded.positions.len().max(1) as f64)).sqrt();
        let edge = mean_edge(&welded.positions, &welded.indices);
        let resolution = edge.min(density);

        // Fine enough already (or as coarse as the material allows): every welded vertex is a node.
        let ratio = resolution / spacing_mm;
        if ratio >= 0.8 {
            let all: Vec<u32> = (0..welded.positions.len() as u32).collect();
            return Nodes {
                positions: welded.positions.clone(),
                normals: welded.normals(mesh, &all),
                prolong: welded.of.iter().map(|&w| vec![(w, 1.0)]).collect(),
                simplified: false,
                spacing_mm: edge,
            };
        }

        let proxy = Proxy::new(&welded, ratio);
        let normals = welded.normals(mesh, &proxy.node_welded);
        let grid = Grid::new(&proxy);
        let welded_normals = welded.normals(
            mesh,
            &(0..welded.positions.len() as u32).collect::<Vec<_>>(),
        );
        let weights_of_welded: Vec<Vec<(u32, f32)>> = (0..welded.positions.len())
            .into_par_iter()
            .map(|w| welded_weights(w, &welded, &welded_normals, &proxy, &grid))
            .collect();
        Nodes {
            positions: proxy.positions,
            normals,
            prolong: welded
                .of
                .iter()
                .map(|&w| weights_of_welded[w as usize].clone())
                .collect(),
            simplified: true,
            spacing_mm: proxy.spacing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_mesh_keeps_its_vertices_and_fine_mesh_is_simplified() {
        let box_mesh = Mesh::cuboid(Vec3::new(40.0, 40.0, 40.0), 8);
        let n = Nodes::build(&box_mesh, 5.0);
        assert!(!n.simplified);
        // Welded: the box's faces share edge vertices.
        assert!(n.positions.len() < box_mesh.positions.len());
        let fine = Mesh::sphere(20.0, 128);
        let n = Nodes::build(&fine, 4.0);
        assert!(n.simplified);
        assert!(
            n.positions.len() < fine.positions.len() / 4,
            "{} nodes",
            n.positions.len()
        );
        assert!(n.spacing_mm > 2.0, "spacing {}", n.spacing_mm);
        for (v, w) in n.prolong.iter().enumerate() {
            let sum: f32 = w.iter().map(|x| x.1).sum();
            assert!((sum - 1.0).abs() < 1e-4);
            // The prolongation reproduces positions to within the proxy's flattening.
            let p: Vec3 = w.iter().map(|(i, x)| n.positions[*i as usize] * *x).sum();
            assert!(p.distance(fine.positions[v]) < 1.0, "vertex {v}");
        }
    }

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        assert_eq!(
            closest_barycentric(DVec3::new(-1.0, -1.0, 0.0), a, b, c),
            [1.0, 0.0, 0.0]
        );
        assert_eq!(
            closest_barycentric(DVec3::new(2.0, 0.0, 1.0), a, b, c),
            [0.0, 1.0, 0.0]
        );
        let inside = closest_barycentric(DVec3::new(0.25, 0.25, 3.0), a, b, c);
        assert!((inside[1] - 0.25).abs() < 1e-12 && (inside[2] - 0.25).abs() < 1e-12);
    }
}
