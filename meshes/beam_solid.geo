// Solid box beam along x, meshed with 4-node tetrahedra.
//
// Parameters (override from Python: femrom.mesh.generate_mesh("beam_solid", {...})):
//   length     extent along x, L [m]                        default 1.0
//   width      extent along y, W [m]                        default 0.1
//   height     extent along z, H [m]                        default 0.05
//   mesh_size  target element edge length h [m]             default 0.05
//
// Physical groups:
//   surfaces  left (x = 0), right (x = L), front (y = 0), back (y = W),
//             bottom (z = 0), top (z = H)
//   volume    beam

SetFactory("OpenCASCADE");

DefineConstant[
  length = {1.0, Min 0, Name "Parameters/length"},
  width = {0.1, Min 0, Name "Parameters/width"},
  height = {0.05, Min 0, Name "Parameters/height"},
  mesh_size = {0.05, Min 0, Name "Parameters/mesh_size"}
];

If (length <= 0 || width <= 0 || height <= 0 || mesh_size <= 0)
  Error("beam_solid.geo: length, width, height and mesh_size must be positive");
  Abort;
EndIf

Box(1) = {0, 0, 0, length, width, height};

// Faces picked by bounding box, with a tolerance of 1e-3 times the smallest dimension
// (OpenCASCADE pads bounding boxes by about 1e-7).
eps = 1e-3 * Min(length, Min(width, height));
left() = Surface In BoundingBox{-eps, -eps, -eps, eps, width + eps, height + eps};
right() = Surface In BoundingBox{length - eps, -eps, -eps, length + eps, width + eps, height + eps};
front() = Surface In BoundingBox{-eps, -eps, -eps, length + eps, eps, height + eps};
back() = Surface In BoundingBox{-eps, width - eps, -eps, length + eps, width + eps, height + eps};
bottom() = Surface In BoundingBox{-eps, -eps, -eps, length + eps, width + eps, eps};
top() = Surface In BoundingBox{-eps, -eps, height - eps, length + eps, width + eps, height + eps};

Physical Surface("left") = left();
Physical Surface("right") = right();
Physical Surface("front") = front();
Physical Surface("back") = back();
Physical Surface("bottom") = bottom();
Physical Surface("top") = top();
Physical Volume("beam") = {1};

MeshSize{PointsOf{Volume{1};}} = mesh_size;
Mesh.MeshSizeMax = mesh_size;
