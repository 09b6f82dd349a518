//! Importers: OBJ and USD garments, BVH motion capture, joint-name maps, skinned glTF bodies, MakeHuman.

pub mod bvh;
pub mod digest;
pub mod gltf_body;
pub mod joint_map;
pub mod makehuman;
pub mod map_suggest;
pub mod obj;
pub mod point_cache;
pub mod usd_mesh;
