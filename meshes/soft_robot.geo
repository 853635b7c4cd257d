// SERPENT-like soft swimming robot: an eel-like body of head, three actuated
// segments joined by stiff couples, a soft tail, and a strain-limiting strip.
//
// Axes: x along the body, from the head's front face (x = 0, clamped) to the
// tail tip (x = length); z the lateral direction, in which the chambers bend
// the body (left: z > 0, right: z < 0); y the vertical (dorsal-ventral)
// direction. The body's cross-section is a height x width rectangle (y x z)
// centred on the x axis.
//
// Along x: head [0, head_length], segment 1, couple 1, segment 2, couple 2,
// segment 3 (each segment segment_length, each couple couple_length), then the
// tail, a ruled loft from the full section to a tip_height x tip_width section
// at x = length (tail length = length - head_length - 3 segment_length
// - 2 couple_length, at least 0.05 length).
//
// Each segment has a left and a right chamber: a row of `chamber_cells`
// box cavities of height chamber_height (y), spanning z from
// strip_thickness/2 + septum to width/2 - wall (left; mirrored on the right),
// separated by ribs of thickness `rib` and kept `end_wall` away from the
// segment's ends (a pneumatic network; the channel joining the cells is not
// modelled: every cell sees the chamber pressure). Pressurising the left
// chamber lengthens the left side and bends the body to the right (-z).
//
// The strain-limiting strip is a thin plate in the x-y mid-plane (|z| <=
// strip_thickness/2, |y| <= strip_height/2) running from the head's rear face
// through the segments and couples to the tail: the neutral plane of the
// lateral bending, stiff in extension. The couples are full sections with the
// strip passing through them.
//
// All pieces are fused by BooleanFragments: neighbouring regions share their
// faces, so the mesh is conforming across every material interface. Every face
// is planar (boxes and a loft between parallel rectangles), so the meshed
// volume equals the geometric one to round-off.
//
// The dimensions are ASSUMPTIONS of the size of the SERPENT robot's published
// model (length about 1.11 m, mass about 9.7 kg); the CAD of the robot is not
// used (docs/soft_robot.md).
//
// Parameters (override from Python: femrom.mesh.generate_mesh("soft_robot", {...})):
//   length           body length along x [m]                             default 1.11
//   height           section height along y [m]                          default 0.12
//   width            section width along z [m]                           default 0.09
//   head_length      [m]                                                 default 0.15
//   segment_length   each actuated segment [m]                           default 0.20
//   couple_length    each couple between segments [m]                    default 0.02
//   tip_height       tail-tip height along y [m]                         default 0.08
//   tip_width        tail-tip width along z [m]                          default 0.02
//   chamber_height   cavity height along y [m]                           default 0.07
//   chamber_cells    cavities per chamber [-]                            default 3
//   rib              rib between cavities of a chamber [m]               default 0.01
//   end_wall         wall between a chamber and its segment's ends [m]   default 0.01
//   wall             outer side wall of a chamber [m]                    default 0.008
//   septum           wall between a chamber and the strip [m]            default 0.008
//   strip_thickness  strip thickness along z [m]                         default 0.006
//   strip_height     strip height along y [m]                            default 0.10
//   mesh_size        target element edge length h [m]                    default 0.03
//
// Physical groups:
//   volumes   head, segment_1, segment_2, segment_3, couple_1, couple_2, tail, strip
//   surfaces  clamp (x = 0), tip (x = length), chamber_<i>_left, chamber_<i>_right
//             (the cavity walls of segment i's chambers, i = 1, 2, 3), skin (the rest
//             of the outer surface)

SetFactory("OpenCASCADE");

DefineConstant[
  length = {1.11, Min 0, Name "Parameters/length"},
  height = {0.12, Min 0, Name "Parameters/height"},
  width = {0.09, Min 0, Name "Parameters/width"},
  head_length = {0.15, Min 0, Name "Parameters/head_length"},
  segment_length = {0.20, Min 0, Name "Parameters/segment_length"},
  couple_length = {0.02, Min 0, Name "Parameters/couple_length"},
  tip_height = {0.08, Min 0, Name "Parameters/tip_height"},
  tip_width = {0.02, Min 0, Name "Parameters/tip_width"},
  chamber_height = {0.07, Min 0, Name "Parameters/chamber_height"},
  chamber_cells = {3, Min 1, Name "Parameters/chamber_cells"},
  rib = {0.01, Min 0, Name "Parameters/rib"},
  end_wall = {0.01, Min 0, Name "Parameters/end_wall"},
  wall = {0.008, Min 0, Name "Parameters/wall"},
  septum = {0.008, Min 0, Name "Parameters/septum"},
  strip_thickness = {0.006, Min 0, Name "Parameters/strip_thickness"},
  strip_height = {0.10, Min 0, Name "Parameters/strip_height"},
  mesh_size = {0.03, Min 0, Name "Parameters/mesh_size"}
];

If (length <= 0 || height <= 0 || width <= 0 || head_length <= 0 || segment_length <= 0 ||
    couple_length <= 0 || tip_height <= 0 || tip_width <= 0 || chamber_height <= 0 ||
    rib <= 0 || end_wall <= 0 || wall <= 0 || septum <= 0 || strip_thickness <= 0 ||
    strip_height <= 0 || mesh_size <= 0)
  Error("soft_robot.geo: dimensions and mesh_size must be positive");
  Abort;
EndIf
tail_start = head_length + 3 * segment_length + 2 * couple_length;
If (length - tail_start < 0.05 * length)
  Error("soft_robot.geo: head, segments and couples (%g) leave no tail in length %g", tail_start, length);
  Abort;
EndIf
If (chamber_height >= height || strip_height >= height || tip_height > height || tip_width > width)
  Error("soft_robot.geo: need chamber_height, strip_height < height and a tip no larger than the section");
  Abort;
EndIf
cells = Round(chamber_cells);
cell = (segment_length - 2 * end_wall - (cells - 1) * rib) / cells;
z_inner = 0.5 * strip_thickness + septum;
z_outer = 0.5 * width - wall;
If (cells < 1 || cell <= 0)
  Error("soft_robot.geo: %g cells with ribs of %g and end walls of %g do not fit in a segment of %g",
        cells, rib, end_wall, segment_length);
  Abort;
EndIf
If (z_outer <= z_inner)
  Error("soft_robot.geo: the chambers do not fit: half-width %g, wall %g, septum %g, strip %g",
        0.5 * width, wall, septum, strip_thickness);
  Abort;
EndIf

h2 = 0.5 * height;
w2 = 0.5 * width;

// -- the pieces, disjoint ------------------------------------------------------------
head = newv; Box(head) = {0, -h2, -w2, head_length, height, width};
strip = newv;
Box(strip) = {head_length, -0.5 * strip_height, -0.5 * strip_thickness,
              tail_start - head_length, strip_height, strip_thickness};

For i In {1 : 3}
  x0~{i} = head_length + (i - 1) * (segment_length + couple_length);
  box = newv; Box(box) = {x0~{i}, -h2, -w2, segment_length, height, width};
  cavities() = {};
  For j In {0 : cells - 1}
    xc = x0~{i} + end_wall + j * (cell + rib);
    c = newv; Box(c) = {xc, -0.5 * chamber_height, z_inner, cell, chamber_height, z_outer - z_inner};
    cavities() += {c};
    c = newv; Box(c) = {xc, -0.5 * chamber_height, -z_outer, cell, chamber_height, z_outer - z_inner};
    cavities() += {c};
  EndFor
  hollow() = BooleanDifference{ Volume{box}; Delete; }{ Volume{cavities()}; Delete; };
  segment~{i}() = BooleanDifference{ Volume{hollow()}; Delete; }{ Volume{strip}; };
EndFor
For i In {1 : 2}
  xk = x0~{i} + segment_length;
  box = newv; Box(box) = {xk, -h2, -w2, couple_length, height, width};
  couple~{i}() = BooleanDifference{ Volume{box}; Delete; }{ Volume{strip}; };
EndFor

// the tail: a ruled loft between the full section and the tip section
pa = newp; Point(pa) = {tail_start, -h2, -w2};
pb = newp; Point(pb) = {tail_start, h2, -w2};
pc = newp; Point(pc) = {tail_start, h2, w2};
pd = newp; Point(pd) = {tail_start, -h2, w2};
la = newl; Line(la) = {pa, pb}; lb = newl; Line(lb) = {pb, pc};
lc = newl; Line(lc) = {pc, pd}; ld = newl; Line(ld) = {pd, pa};
root = newcl; Curve Loop(root) = {la, lb, lc, ld};
qa = newp; Point(qa) = {length, -0.5 * tip_height, -0.5 * tip_width};
qb = newp; Point(qb) = {length, 0.5 * tip_height, -0.5 * tip_width};
qc = newp; Point(qc) = {length, 0.5 * tip_height, 0.5 * tip_width};
qd = newp; Point(qd) = {length, -0.5 * tip_height, 0.5 * tip_width};
ma = newl; Line(ma) = {qa, qb}; mb = newl; Line(mb) = {qb, qc};
mc = newl; Line(mc) = {qc, qd}; md = newl; Line(md) = {qd, qa};
end = newcl; Curve Loop(end) = {ma, mb, mc, md};
tail = newv; Ruled ThruSections(tail) = {root, end};

// -- fused: shared faces between neighbouring regions --------------------------------
BooleanFragments{ Volume{:}; Delete; }{}

// Regions picked by bounding box (tolerance 1e-3 of the thinnest part; OpenCASCADE
// pads boxes by about 1e-7). Each region lies in the slab of its x range; the strip
// spans several slabs, so it falls in none of them.
eps = 1e-3 * Min(strip_thickness, Min(rib, Min(wall, septum)));
big = 2 * (height + width);
head_v() = Volume In BoundingBox{-eps, -big, -big, head_length + eps, big, big};
tail_v() = Volume In BoundingBox{tail_start - eps, -big, -big, length + eps, big, big};
strip_v() = Volume In BoundingBox{head_length - eps, -0.5 * strip_height - eps, -0.5 * strip_thickness - eps,
                                  tail_start + eps, 0.5 * strip_height + eps, 0.5 * strip_thickness + eps};
For i In {1 : 3}
  segment_v~{i}() = Volume In BoundingBox{x0~{i} - eps, -big, -big, x0~{i} + segment_length + eps, big, big};
EndFor
For i In {1 : 2}
  xk = x0~{i} + segment_length;
  couple_v~{i}() = Volume In BoundingBox{xk - eps, -big, -big, xk + couple_length + eps, big, big};
EndFor

Physical Volume("head") = head_v();
Physical Volume("segment_1") = segment_v~{1}();
Physical Volume("segment_2") = segment_v~{2}();
Physical Volume("segment_3") = segment_v~{3}();
Physical Volume("couple_1") = couple_v~{1}();
Physical Volume("couple_2") = couple_v~{2}();
Physical Volume("tail") = tail_v();
Physical Volume("strip") = strip_v();

// -- named faces ----------------------------------------------------------------------
clamp() = Surface In BoundingBox{-eps, -big, -big, eps, big, big};
tip() = Surface In BoundingBox{length - eps, -big, -big, length + eps, big, big};
chambers() = {};
For i In {1 : 3}
  xa = x0~{i} + end_wall - eps;
  xb = x0~{i} + segment_length - end_wall + eps;
  chamber_left~{i}() = Surface In BoundingBox{xa, -0.5 * chamber_height - eps, z_inner - eps,
                                              xb, 0.5 * chamber_height + eps, z_outer + eps};
  chamber_right~{i}() = Surface In BoundingBox{xa, -0.5 * chamber_height - eps, -z_outer - eps,
                                               xb, 0.5 * chamber_height + eps, -z_inner + eps};
  chambers() += {chamber_left~{i}(), chamber_right~{i}()};
EndFor
skin() = Abs(CombinedBoundary{ Volume{:}; });
skin() -= clamp();
skin() -= tip();
skin() -= chambers();

Physical Surface("clamp") = clamp();
Physical Surface("tip") = tip();
For i In {1 : 3}
  Physical Surface(Sprintf("chamber_%g_left", i)) = chamber_left~{i}();
  Physical Surface(Sprintf("chamber_%g_right", i)) = chamber_right~{i}();
EndFor
Physical Surface("skin") = skin();

MeshSize{ PointsOf{ Volume{:}; } } = mesh_size;
Mesh.MeshSizeMax = mesh_size;
