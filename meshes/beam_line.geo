// Straight Euler-Bernoulli beam axis along x, meshed with 2-node line elements.
//
// Parameters (override from Python: femrom.mesh.generate_mesh("beam_line", {...})):
//   length          beam length L [m]                                   default 1.0
//   mesh_size       target element length h [m]                         default 0.1
//   probe_position  position of an interior node, as a fraction of L,
//                   strictly between 0 and 1 [-]                        default 0.5
//
// Physical groups:
//   points  left (x = 0), right (x = L), probe (x = probe_position * L)
//   curve   beam (the whole axis)

DefineConstant[
  length = {1.0, Min 0, Name "Parameters/length"},
  mesh_size = {0.1, Min 0, Name "Parameters/mesh_size"},
  probe_position = {0.5, Min 0, Max 1, Name "Parameters/probe_position"}
];

If (length <= 0 || mesh_size <= 0)
  Error("beam_line.geo: length and mesh_size must be positive");
  Abort;
EndIf
If (probe_position <= 0 || probe_position >= 1)
  Error("beam_line.geo: probe_position must lie strictly between 0 and 1");
  Abort;
EndIf

Point(1) = {0, 0, 0, mesh_size};
Point(2) = {probe_position * length, 0, 0, mesh_size};
Point(3) = {length, 0, 0, mesh_size};
Line(1) = {1, 2};
Line(2) = {2, 3};

Physical Point("left") = {1};
Physical Point("right") = {3};
Physical Point("probe") = {2};
Physical Curve("beam") = {1, 2};
