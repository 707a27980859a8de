//! volmorph-mesh: Indexed polygon meshes, OBJ/STL/PLY/OFF, normals and validation.
