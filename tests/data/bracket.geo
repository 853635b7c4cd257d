// L-shaped bracket for the [rom] pipeline tests: a vertical leg clamped at its
// foot (z = 0) and a horizontal arm along x whose free end face is pushed.
//
// Physical groups: surfaces foot (z = 0 under the leg), end (x = arm); volume bracket.
SetFactory("OpenCASCADE");

DefineConstant[
  leg = {0.2, Min 0, Name "Parameters/leg"},
  arm = {0.15, Min 0, Name "Parameters/arm"},
  thickness = {0.02, Min 0, Name "Parameters/thickness"},
  depth = {0.04, Min 0, Name "Parameters/depth"},
  mesh_size = {0.012, Min 0, Name "Parameters/mesh_size"}
];

Box(1) = {0, 0, 0, thickness, depth, leg};
Box(2) = {0, 0, leg - thickness, arm, depth, thickness};
v() = BooleanUnion{ Volume{1}; Delete; }{ Volume{2}; Delete; };

eps = 1e-3 * thickness;
Physical Surface("foot") = Surface In BoundingBox{-eps, -eps, -eps, thickness + eps, depth + eps, eps};
Physical Surface("end") = Surface In BoundingBox{arm - eps, -eps, leg - thickness - eps,
                                                 arm + eps, depth + eps, leg + eps};
Physical Volume("bracket") = v();

Mesh.MeshSizeMax = mesh_size;
