// Soft-robotic fishtail: a tapered silicone tail with two fluidic-elastomer chambers.
//
// The tail runs along +x from the head face (x = 0, clamped to the rigid head)
// to the tip face (x = length). Its cross-section is a rectangle that tapers
// linearly from head_width x head_height (y x z) at the head to tip_width x
// tip_height at the tip. Two chambers, left (y > 0) and right (y < 0), run
// along the tail from chamber_start to chamber_end; each is a row of
// `segments` tapered boxes separated by ribs of thickness `rib` (a ribbed
// "pneumatic network"; the channel connecting the segments is not modelled:
// every segment sees the chamber pressure). The rows are separated by a
// central wall (septum) of thickness `septum` and kept `wall` away from the
// flanks; their height is chamber_fraction of the local tail height.
// Pressurising one chamber pushes its ribs apart, stretches its side of the
// tail and bends the tail towards the other side. (One long chamber per side
// barely bends it in linear elasticity at nu near 0.5: its walls bulge and
// shorten; measured at h = 5 mm and 20 kPa: tip 0.09 mm with one
// segment, 1.95 mm with six.) Compare the fluidic elastomer actuators of
// Marchese, Onal & Rus, Soft Robotics 1, 2014, and the MORwiki "Artificial
// Fishtail" of Siebelts, Kater & Meurer, IFAC-PapersOnLine 51, 2018.
//
// The dimensions are ASSUMPTIONS of the order of the MORwiki model's tail
// (about a decimetre long); its exact CAD data are not published with the
// benchmark matrices. The MORwiki model also has a central carbon beam, which
// this geometry leaves out (the septum is silicone).
//
// Parameters (override from Python: femrom.mesh.generate_mesh("fishtail", {...})):
//   length            tail length along x [m]                          default 0.10
//   head_width        y extent at the head [m]                         default 0.030
//   head_height       z extent at the head [m]                         default 0.050
//   tip_width         y extent at the tip [m]                          default 0.012
//   tip_height        z extent at the tip [m]                          default 0.020
//   wall              flank wall thickness outside the chambers [m]     default 0.003
//   septum            central wall between the chambers [m]            default 0.004
//   chamber_start     x where the chambers begin [m]                   default 0.010
//   chamber_end       x where the chambers end [m]                     default 0.085
//   chamber_fraction  chamber height / local tail height [-]           default 0.6
//   segments          chamber segments per side [-]                    default 6
//   rib               rib thickness between segments [m]               default 0.002
//   mesh_size         target element edge length h [m]                 default 0.006
//
// Physical groups:
//   surfaces  clamp (x = 0), tip (x = length), chamber_left (inner walls of
//             the y > 0 chamber), chamber_right (inner walls of the y < 0 chamber),
//             skin (the remaining outer surface)
//   volume    body

SetFactory("OpenCASCADE");

DefineConstant[
  length = {0.10, Min 0, Name "Parameters/length"},
  head_width = {0.030, Min 0, Name "Parameters/head_width"},
  head_height = {0.050, Min 0, Name "Parameters/head_height"},
  tip_width = {0.012, Min 0, Name "Parameters/tip_width"},
  tip_height = {0.020, Min 0, Name "Parameters/tip_height"},
  wall = {0.003, Min 0, Name "Parameters/wall"},
  septum = {0.004, Min 0, Name "Parameters/septum"},
  chamber_start = {0.010, Min 0, Name "Parameters/chamber_start"},
  chamber_end = {0.085, Min 0, Name "Parameters/chamber_end"},
  chamber_fraction = {0.6, Min 0, Max 1, Name "Parameters/chamber_fraction"},
  segments = {6, Min 1, Name "Parameters/segments"},
  rib = {0.002, Min 0, Name "Parameters/rib"},
  mesh_size = {0.006, Min 0, Name "Parameters/mesh_size"}
];

If (length <= 0 || head_width <= 0 || head_height <= 0 || tip_width <= 0 || tip_height <= 0 ||
    mesh_size <= 0 || wall <= 0 || septum <= 0)
  Error("fishtail.geo: dimensions and mesh_size must be positive");
  Abort;
EndIf
If (chamber_start <= 0 || chamber_end >= length || chamber_end <= chamber_start ||
    chamber_fraction <= 0 || chamber_fraction >= 1)
  Error("fishtail.geo: need 0 < chamber_start < chamber_end < length and 0 < chamber_fraction < 1");
  Abort;
EndIf

// The body: a ruled loft between its head and tip sections (rectangles).
// Chamber segment j of side `side` (+1 left, -1 right) spans [xa, xb]; its two
// end sections are rectangles too. Every section {xs} x [y0, y1] x [z0, z1]
// becomes a curve loop `loop`.
seg = (chamber_end - chamber_start - (segments - 1) * rib) / segments;
If (segments < 1 || seg <= 0)
  Error("fishtail.geo: %g segments with ribs of %g do not fit in [%g, %g]", segments, rib,
        chamber_start, chamber_end);
  Abort;
EndIf
cavities() = {};
For k In {-2 : 2 * segments * 2 - 1}
  // k = -2, -1: the body's head and tip; k >= 0: chamber sections
  If (k < 0)
    xs = (k + 2) * length;
  Else
    j = Floor(k / 4);            // segment
    side = 1 - 2 * ((Floor(k / 2)) % 2); // +1 left, -1 right
    xs = chamber_start + j * (seg + rib) + (k % 2) * seg;
  EndIf
  hw = 0.5 * (head_width + (tip_width - head_width) * xs / length);   // local half-width
  hh = 0.5 * (head_height + (tip_height - head_height) * xs / length); // local half-height
  If (k < 0)
    y0 = -hw; y1 = hw; z0 = -hh; z1 = hh;
  Else
    inner = 0.5 * septum; outer = hw - wall;
    If (outer <= inner)
      Error("fishtail.geo: the chambers do not fit at x = %g: half-width %g, wall %g, septum %g",
            xs, hw, wall, septum);
      Abort;
    EndIf
    If (side > 0)
      y0 = inner; y1 = outer;
    Else
      y0 = -outer; y1 = -inner;
    EndIf
    z0 = -chamber_fraction * hh; z1 = chamber_fraction * hh;
  EndIf
  pa = newp; Point(pa) = {xs, y0, z0};
  pb = newp; Point(pb) = {xs, y1, z0};
  pc = newp; Point(pc) = {xs, y1, z1};
  pd = newp; Point(pd) = {xs, y0, z1};
  la = newl; Line(la) = {pa, pb};
  lb = newl; Line(lb) = {pb, pc};
  lc = newl; Line(lc) = {pc, pd};
  ld = newl; Line(ld) = {pd, pa};
  loop = newcl; Curve Loop(loop) = {la, lb, lc, ld};
  If (k == -2 || (k >= 0 && k % 2 == 0))
    first = loop;
  Else
    v = newv;
    Ruled ThruSections(v) = {first, loop};
    If (k == -1)
      body = v;
    Else
      cavities() += {v};
    EndIf
  EndIf
EndFor

tail() = BooleanDifference{ Volume{body}; Delete; }{ Volume{cavities()}; Delete; };

// Faces picked by bounding box with a tolerance of 1e-3 times the smallest
// dimension (OpenCASCADE pads bounding boxes by about 1e-7).
eps = 1e-3 * Min(wall, Min(septum, tip_width));
big = 2 * (head_width + head_height);
clamp() = Surface In BoundingBox{-eps, -big, -big, eps, big, big};
tip() = Surface In BoundingBox{length - eps, -big, -big, length + eps, big, big};
chamber_left() = Surface In BoundingBox{chamber_start - eps, 0.5 * septum - eps, -big,
                                        chamber_end + eps, big, big};
// (the outer skin spans the whole length: it never fits in a chamber's box)
chamber_right() = Surface In BoundingBox{chamber_start - eps, -big, -big,
                                         chamber_end + eps, -0.5 * septum + eps, big};
all() = Abs(Boundary{ Volume{tail()}; });
skin() = all();
skin() -= clamp();
skin() -= tip();
skin() -= chamber_left();
skin() -= chamber_right();

Physical Surface("clamp") = clamp();
Physical Surface("tip") = tip();
Physical Surface("chamber_left") = chamber_left();
Physical Surface("chamber_right") = chamber_right();
Physical Surface("skin") = skin();
Physical Volume("body") = tail();

MeshSize{PointsOf{Volume{tail()};}} = mesh_size;
Mesh.MeshSizeMax = mesh_size;
