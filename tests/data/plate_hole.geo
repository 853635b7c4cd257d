// A thin rectangular plate with an off-centre circular hole, clamped at x = 0.
//
// Physical groups: surfaces clamp (x = 0), tip (x = length), hole (the bore); volume plate.
SetFactory("OpenCASCADE");

DefineConstant[
  length = {0.2, Min 0, Name "Parameters/length"},
  width = {0.1, Min 0, Name "Parameters/width"},
  thickness = {0.004, Min 0, Name "Parameters/thickness"},
  hole_x = {0.13, Min 0, Name "Parameters/hole_x"},
  hole_y = {0.062, Min 0, Name "Parameters/hole_y"},
  hole_radius = {0.018, Min 0, Name "Parameters/hole_radius"},
  mesh_size = {0.01, Min 0, Name "Parameters/mesh_size"}
];

Box(1) = {0, 0, 0, length, width, thickness};
Cylinder(2) = {hole_x, hole_y, -thickness, 0, 0, 3 * thickness, hole_radius};
v() = BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; };

eps = 1e-3 * thickness;
Physical Surface("clamp") = Surface In BoundingBox{-eps, -eps, -eps, eps, width + eps, thickness + eps};
Physical Surface("tip") = Surface In BoundingBox{length - eps, -eps, -eps, length + eps, width + eps, thickness + eps};
Physical Surface("hole") = Surface In BoundingBox{hole_x - hole_radius - eps, hole_y - hole_radius - eps, -eps,
                                                  hole_x + hole_radius + eps, hole_y + hole_radius + eps,
                                                  thickness + eps};
Physical Volume("plate") = v();

Mesh.MeshSizeMax = mesh_size;
