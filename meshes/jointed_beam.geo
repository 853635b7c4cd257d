// Half-thickness Brake-Reuss beam: two bolted halves with a lap joint (Chen et al.,
// MSSP 166:108401, 2022; data and drawings in the shared folder data/brb/).
//
// Axes: x along the beam (0 to length), y the vibration direction (0 = bottom,
// thickness = top), z across the width (-width/2 to width/2, centre z = 0).
// Each half is a full thickness x width section for (length - overlap)/2, then a
// layer of half the thickness along the overlap, centred on the beam: the lap joint
// runs from x0 = (length - overlap)/2 to x1 = x0 + overlap, and the two layers touch
// on the interface plane y = thickness/2. By default the LEFT half's layer is the
// TOP one, as in the impact-test drawing (ImpactShematic.jpg, the test of the
// hammer data); the beam drawing (BeamSchematic.jpg, panel b) shows the mirror
// image: left_layer_on_top = 0.
//
// The two step faces where a layer ends against the other half's full section
// (x = x0 and x = x1, half the thickness each) touch but are free surfaces: no
// contact is modelled there (their meshes need not match). With bonded = 1 the
// halves are fused instead (OpenCASCADE fragments: shared interface and step
// faces, one conforming mesh, no duplicated node): with holes = 0 this is the
// uniform 720 mm bar of the bonded reference.
//
// Bolts: three holes of diameter bolt_hole_diameter through both layers at
// x = length/2 + (-1, 0, 1) bolt_pitch, z = 0 (holes = 0: no holes). The washer
// footprints are imprinted on the outer faces of the joint: annuli (holes = 1) or
// disks (holes = 0) of outer radius washer_radius, on the top (y = thickness) and
// the bottom (y = 0). A bolt preload (about 12 kN per bolt) is a pressure on the
// top and bottom washer patches of that bolt, pressing the layers together; the
// bolt shank is not modelled (the hole walls are free surfaces, named for later use).
//
// Interface: with bonded = 0 each half keeps its own nodes on the interface plane.
// The two faces are meshed identically: the face of the right half is declared
// periodic to the face of the left half with the identity transform, so gmsh copies
// the left face's surface mesh node for node onto the right face; the two volumes
// are then meshed separately from these boundary meshes (duplicated, coincident
// nodes; matching triangles).
//
// Sensors are square patches of side sensor_size centred on the beam's centre line
// (z = 0), imprinted on the top or bottom face (footprint size and z = 0 are
// assumptions; the positions are from the drawings):
//   acc1     top,    x = 0.0254 (2.54 cm from the left end)
//   acc2     bottom, x = length - 0.1651 (16.51 cm from the right end)
//   acc3     bottom, x = length - 0.0762 (7.62 cm from the right end)
//   impact   top,    x = length - 0.0762 (the hammer strikes acc3's position from the top)
//   shaker1  bottom, x = 0.0762, shaker2 bottom, x = 0.1778 (shaker attachment points of
//            brb_geometry.json; the face is an assumption: the drawing shows the top view)
// A mesh node sits at the centre of each patch (physical points acc1_point, ...; they
// are in the .msh file, scikit-fem drops point groups).
//
// Parameters (override from Python: femrom.mesh.generate_mesh("jointed_beam", {...})):
//   length              total length L [m]                                    default 0.720
//   width               z extent W [m]                                        default 0.0254
//   thickness           y extent T, the vibration direction [m]               default 0.0127
//   overlap             lap-joint length, centred on the beam [m]             default 0.120
//   bolt_pitch          distance between neighbouring bolts [m]               default 0.030
//   bolt_hole_diameter  [m]                                                   default 0.0085
//   washer_radius       outer radius of the washer footprint, 11/32 in [m]    default 0.00873125
//   sensor_size         side of the square sensor patches [m]                 default 0.00635
//   holes               1: cut the bolt holes, 0: solid overlap [-]           default 1
//   bonded              1: fuse the halves (shared nodes), 0: jointed [-]     default 0
//   left_layer_on_top   1: the left half's layer is the top one [-]           default 1
//   mesh_size           element size away from the joint [m]                  default 0.00635
//   joint_mesh_size     element size over the overlap (x0 to x1) [m]          default 0.003175
//   circle_segments     minimum segments per full circle (holes, washers) [-] default 12
//
// Physical groups:
//   volumes   left_half, right_half
//   surfaces  interface_left, interface_right (the left / right half's face on the
//             interface plane; with bonded = 1 both name the same shared face),
//             washer_top_1, washer_top_2, washer_top_3, washer_bottom_1, washer_bottom_2,
//             washer_bottom_3 (bolt 1 at the smallest x), bolt_hole_1, bolt_hole_2,
//             bolt_hole_3 (hole walls of both halves; holes = 1 only), left_end (x = 0),
//             right_end (x = L), acc1, acc2, acc3, impact, shaker1, shaker2
//   points    acc1_point, acc2_point, acc3_point, impact_point, shaker1_point, shaker2_point

SetFactory("OpenCASCADE");

DefineConstant[
  length = {0.720, Min 0, Name "Parameters/length"},
  width = {0.0254, Min 0, Name "Parameters/width"},
  thickness = {0.0127, Min 0, Name "Parameters/thickness"},
  overlap = {0.120, Min 0, Name "Parameters/overlap"},
  bolt_pitch = {0.030, Min 0, Name "Parameters/bolt_pitch"},
  bolt_hole_diameter = {0.0085, Min 0, Name "Parameters/bolt_hole_diameter"},
  washer_radius = {0.00873125, Min 0, Name "Parameters/washer_radius"},
  sensor_size = {0.00635, Min 0, Name "Parameters/sensor_size"},
  holes = {1, Choices {0, 1}, Name "Parameters/holes"},
  bonded = {0, Choices {0, 1}, Name "Parameters/bonded"},
  left_layer_on_top = {1, Choices {0, 1}, Name "Parameters/left_layer_on_top"},
  mesh_size = {0.00635, Min 0, Name "Parameters/mesh_size"},
  joint_mesh_size = {0.003175, Min 0, Name "Parameters/joint_mesh_size"},
  circle_segments = {12, Min 3, Name "Parameters/circle_segments"}
];

// ---- checks ---------------------------------------------------------------------------
If (length <= 0 || width <= 0 || thickness <= 0 || overlap <= 0 || mesh_size <= 0 ||
    joint_mesh_size <= 0 || sensor_size <= 0 || washer_radius <= 0 || bolt_pitch <= 0)
  Error("jointed_beam.geo: lengths, sizes and mesh sizes must be positive");
  Abort;
EndIf
If ((holes != 0 && holes != 1) || (bonded != 0 && bonded != 1) ||
    (left_layer_on_top != 0 && left_layer_on_top != 1))
  Error("jointed_beam.geo: holes, bonded and left_layer_on_top must be 0 or 1");
  Abort;
EndIf
If (circle_segments < 3)
  Error("jointed_beam.geo: circle_segments must be at least 3, got %g", circle_segments);
  Abort;
EndIf
If (overlap >= length)
  Error("jointed_beam.geo: overlap = %g must be shorter than length = %g", overlap, length);
  Abort;
EndIf
If (holes && (bolt_hole_diameter <= 0 || bolt_hole_diameter >= 2 * washer_radius))
  Error("jointed_beam.geo: need 0 < bolt_hole_diameter < 2 washer_radius, got %g and %g",
        bolt_hole_diameter, washer_radius);
  Abort;
EndIf
If (2 * washer_radius >= width || 2 * washer_radius >= bolt_pitch ||
    bolt_pitch + washer_radius >= overlap / 2)
  Error("jointed_beam.geo: the washers (radius %g, pitch %g) must fit in the overlap (%g x %g) without touching",
        washer_radius, bolt_pitch, overlap, width);
  Abort;
EndIf
If (sensor_size >= width || 0.0254 - sensor_size / 2 <= 0 ||
    0.1778 + sensor_size / 2 >= (length - overlap) / 2 ||
    length - 0.1651 - sensor_size / 2 <= (length + overlap) / 2)
  Error("jointed_beam.geo: the sensor patches (side %g) must fit on the full sections away from the joint",
        sensor_size);
  Abort;
EndIf

// ---- the two halves ---------------------------------------------------------------------
L = length; W = width; T = thickness; h = T / 2;
x0 = (L - overlap) / 2; x1 = x0 + overlap; xc = L / 2;
y_left_layer = left_layer_on_top * h;        // bottom of the left half's layer
y_right_layer = (1 - left_layer_on_top) * h; // bottom of the right half's layer

Box(1) = {0, 0, -W / 2, x0, T, W};
Box(2) = {x0, y_left_layer, -W / 2, overlap, h, W};
Box(3) = {x0, y_right_layer, -W / 2, overlap, h, W};
Box(4) = {x1, 0, -W / 2, L - x1, T, W};
left() = BooleanUnion{ Volume{1}; Delete; }{ Volume{2}; Delete; };
right() = BooleanUnion{ Volume{4}; Delete; }{ Volume{3}; Delete; };

If (holes)
  shanks() = {};
  For i In {0 : 2}
    shank = newv;
    Cylinder(shank) = {xc + (i - 1) * bolt_pitch, -T, 0, 0, 3 * T, 0, bolt_hole_diameter / 2};
    shanks() += shank;
  EndFor
  left() = BooleanDifference{ Volume{left()}; Delete; }{ Volume{shanks()}; };
  right() = BooleanDifference{ Volume{right()}; Delete; }{ Volume{shanks()}; Delete; };
EndIf

// ---- imprinted patches: washers and sensors ------------------------------------------------
// A flat patch in the plane y = y_face: made in the xy plane around the origin, turned
// by +90 degrees about x ((x, y, 0) -> (x, 0, y)), then moved to (x_centre, y_face, 0).
top_patches() = {}; bottom_patches() = {};
For i In {0 : 2}
  For side In {0 : 1}       // 0: bottom face (y = 0), 1: top face (y = T)
    outer = news; Disk(outer) = {0, 0, 0, washer_radius, washer_radius};
    patch = outer;
    If (holes)
      inner = news; Disk(inner) = {0, 0, 0, bolt_hole_diameter / 2, bolt_hole_diameter / 2};
      ring() = BooleanDifference{ Surface{outer}; Delete; }{ Surface{inner}; Delete; };
      patch = ring(0);
    EndIf
    Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{patch}; }
    Translate {xc + (i - 1) * bolt_pitch, side * T, 0} { Surface{patch}; }
    If (side == 1)
      top_patches() += patch;
    Else
      bottom_patches() += patch;
    EndIf
  EndFor
EndFor
// sensor centres x, and face (1 top, 0 bottom), in the order acc1, acc2, acc3, impact,
// shaker1, shaker2
sensor_x() = {0.0254, L - 0.1651, L - 0.0762, L - 0.0762, 0.0762, 0.1778};
sensor_top() = {1, 0, 0, 1, 0, 0};
sensor_points() = {};
left_patches() = {}; right_patches() = {};
For k In {0 : 5}
  square = news;
  Rectangle(square) = {-sensor_size / 2, -sensor_size / 2, 0, sensor_size, sensor_size};
  Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{square}; }
  Translate {sensor_x(k), sensor_top(k) * T, 0} { Surface{square}; }
  centre = newp; Point(centre) = {sensor_x(k), sensor_top(k) * T, 0};
  sensor_points() += centre;
  If (sensor_x(k) < xc)
    left_patches() += square;
  Else
    right_patches() += square;
  EndIf
EndFor
// The top washer patches lie on the half whose layer is on top.
If (left_layer_on_top)
  left_patches() += top_patches(); right_patches() += bottom_patches();
Else
  left_patches() += bottom_patches(); right_patches() += top_patches();
EndIf
left() = BooleanFragments{ Volume{left()}; Delete; }{ Surface{left_patches()}; Delete; };
right() = BooleanFragments{ Volume{right()}; Delete; }{ Surface{right_patches()}; Delete; };
If (bonded)
  BooleanFragments{ Volume{:}; Delete; }{}
EndIf

// ---- picking entities by bounding box ----------------------------------------------------------
// tolerance: 1e-3 times the smallest dimension (OpenCASCADE pads boxes by about 1e-7)
eps = 1e-3 * Min(Min(T, W), Min(sensor_size, washer_radius));
left_volume() = Volume In BoundingBox{-eps, -eps, -W / 2 - eps, x1 + eps, T + eps, W / 2 + eps};
right_volume() = Volume In BoundingBox{x0 - eps, -eps, -W / 2 - eps, L + eps, T + eps, W / 2 + eps};
If (#left_volume() != 1 || #right_volume() != 1)
  Error("jointed_beam.geo: expected one volume per half, found %g and %g", #left_volume(), #right_volume());
  Abort;
EndIf

on_plane() = Surface In BoundingBox{x0 - eps, h - eps, -W / 2 - eps, x1 + eps, h + eps, W / 2 + eps};
left_faces() = Abs(Boundary{ Volume{left_volume()}; });
right_faces() = Abs(Boundary{ Volume{right_volume()}; });
interface_left() = {}; interface_right() = {};
For k In {0 : #on_plane() - 1}
  For m In {0 : #left_faces() - 1}
    If (on_plane(k) == left_faces(m))
      interface_left() += on_plane(k);
    EndIf
  EndFor
  For m In {0 : #right_faces() - 1}
    If (on_plane(k) == right_faces(m))
      interface_right() += on_plane(k);
    EndIf
  EndFor
EndFor
If (#interface_left() != 1 || #interface_right() != 1)
  Error("jointed_beam.geo: expected one interface face per half, found %g and %g",
        #interface_left(), #interface_right());
  Abort;
EndIf

For i In {0 : 2}
  xb = xc + (i - 1) * bolt_pitch;
  washer_top~{i}() = Surface In BoundingBox{xb - washer_radius - eps, T - eps, -washer_radius - eps,
                                           xb + washer_radius + eps, T + eps, washer_radius + eps};
  washer_bottom~{i}() = Surface In BoundingBox{xb - washer_radius - eps, -eps, -washer_radius - eps,
                                              xb + washer_radius + eps, eps, washer_radius + eps};
  If (holes)
    r = bolt_hole_diameter / 2;
    bolt_hole~{i}() = Surface In BoundingBox{xb - r - eps, -eps, -r - eps, xb + r + eps, T + eps, r + eps};
  EndIf
EndFor
For k In {0 : 5}
  yk = sensor_top(k) * T;
  patch() = Surface In BoundingBox{sensor_x(k) - sensor_size / 2 - eps, yk - eps, -sensor_size / 2 - eps,
                                   sensor_x(k) + sensor_size / 2 + eps, yk + eps, sensor_size / 2 + eps};
  sensor~{k}() = patch();
  Point{sensor_points(k)} In Surface{patch(0)};   // a mesh node at the sensor's centre
EndFor
left_end() = Surface In BoundingBox{-eps, -eps, -W / 2 - eps, eps, T + eps, W / 2 + eps};
right_end() = Surface In BoundingBox{L - eps, -eps, -W / 2 - eps, L + eps, T + eps, W / 2 + eps};


// ---- conforming interface faces with duplicated nodes ------------------------------------------
If (!bonded)
  Periodic Surface{interface_right()} = {interface_left()} Translate {0, 0, 0};
EndIf

// ---- physical groups ------------------------------------------------------------------------------
Physical Volume("left_half") = left_volume();
Physical Volume("right_half") = right_volume();
Physical Surface("interface_left") = interface_left();
If (bonded)
  Physical Surface("interface_right") = interface_left();
Else
  Physical Surface("interface_right") = interface_right();
EndIf
For i In {0 : 2}
  Physical Surface(Sprintf("washer_top_%g", i + 1)) = washer_top~{i}();
  Physical Surface(Sprintf("washer_bottom_%g", i + 1)) = washer_bottom~{i}();
  If (holes)
    Physical Surface(Sprintf("bolt_hole_%g", i + 1)) = bolt_hole~{i}();
  EndIf
EndFor
Physical Surface("left_end") = left_end();
Physical Surface("right_end") = right_end();
Physical Surface("acc1") = sensor_0(); Physical Point("acc1_point") = sensor_points(0);
Physical Surface("acc2") = sensor_1(); Physical Point("acc2_point") = sensor_points(1);
Physical Surface("acc3") = sensor_2(); Physical Point("acc3_point") = sensor_points(2);
Physical Surface("impact") = sensor_3(); Physical Point("impact_point") = sensor_points(3);
Physical Surface("shaker1") = sensor_4(); Physical Point("shaker1_point") = sensor_points(4);
Physical Surface("shaker2") = sensor_5(); Physical Point("shaker2_point") = sensor_points(5);

// ---- mesh sizes ---------------------------------------------------------------------------------------
Field[1] = Box;
Field[1].VIn = joint_mesh_size;
Field[1].VOut = mesh_size;
Field[1].XMin = x0; Field[1].XMax = x1;
Field[1].YMin = -T; Field[1].YMax = 2 * T;
Field[1].ZMin = -W; Field[1].ZMax = W;
Field[1].Thickness = Max(mesh_size, joint_mesh_size);  // transition layer outside the box
Background Field = 1;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromCurvature = circle_segments;
Mesh.MeshSizeMax = Max(mesh_size, joint_mesh_size);
