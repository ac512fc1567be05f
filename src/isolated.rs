//! placeholder until merge
use crate::mesh::TriMesh;
/// placeholder
pub fn icosphere(_level: u32, _radius: f32) -> TriMesh {
    TriMesh::default()
}
