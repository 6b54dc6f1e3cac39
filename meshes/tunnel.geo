// A tunnel in a plane-strain slice of ground, half model (x >= 0; the plane x = 0 through the
// tunnel's axis is a plane of symmetry). In the x-z section: ground from z = 0 (base) to
// z = Hg (the ground surface), W wide; the opening of outer diameter D (the lining's outside)
// with its crown at cover C below the surface; the lining, thickness t, inside it; the DEM
// zone a ring of thickness a around the lining (cut by the ground surface when a > C), and, when
// chimney > 0, the band |x| < chimney above the axis up to the ground surface (the ground that
// falls after the crown); FE soil beyond. The section is meshed with triangles, h in the lining and the ring growing to h_far
// `grow` beyond it, and extruded along y in layers h_y thick (Ly in all). When B > 0 the ground
// surface over |x| < B/2 is a strip of its own (a surcharge: a rigid strip footing on it).
// Physical names: volumes "lining", "zone", "soil"; surfaces "ground" (z = Hg, but the strip),
// "strip" (when B > 0), "base" (z = 0), "far" (x = W), "axis" (x = 0), "sides" (y = 0 and
// y = Ly), "intrados" (the lining's inside face). The zone's faces shared with the lining and the soil are the
// coupling interface, found from the cells: no group for it.
SetFactory("OpenCASCADE");
DefineConstant[ D = {0.1, Name "Parameters/D"}, C = {0.1, Name "Parameters/C"},
                t = {0.005, Name "Parameters/t"}, a = {0.05, Name "Parameters/a"},
                W = {0.4, Name "Parameters/W"}, below = {0.2, Name "Parameters/below"},
                Ly = {0.01, Name "Parameters/Ly"}, h = {0.005, Name "Parameters/h"},
                h_far = {0.02, Name "Parameters/h_far"}, grow = {0.1, Name "Parameters/grow"},
                chimney = {0, Name "Parameters/chimney"}, B = {0, Name "Parameters/B"} ];
DefineConstant[ h_y = {h, Name "Parameters/h_y"} ];   // the layers' thickness along y
Hg = below + D + C;          // the ground surface
zc = below + D / 2;          // the tunnel's axis
Rectangle(1) = {0, 0, 0, W, Hg};
Disk(2) = {0, zc, 0, D / 2 + a};
Disk(3) = {0, zc, 0, D / 2};
Disk(4) = {0, zc, 0, D / 2 - t};
outline = 2;             // the zone's outer outline: the ring's disk, with the chimney's band
If (chimney > 0)
  Rectangle(5) = {-chimney, zc, 0, 2 * chimney, Hg - zc};
  joined() = BooleanUnion{ Surface{2}; Delete; }{ Surface{5}; Delete; };
  outline = joined(0);
EndIf
If (B > 0)               // a vertex on the ground surface at x = B/2: the strip's edge
  Point(100) = {B / 2, Hg, 0};
  BooleanFragments{ Surface{1}; Delete; }{ Surface{outline, 3, 4}; Point{100}; Delete; }
Else
  BooleanFragments{ Surface{1}; Delete; }{ Surface{outline, 3, 4}; Delete; }
EndIf
eps = 1e-4 * (W + Hg);   // OpenCASCADE bounding boxes carry a tolerance
// keep the pieces inside the ground (x >= 0, z <= Hg) and outside the opening
keep() = Surface In BoundingBox{-eps, -eps, -eps, W + eps, Hg + eps, eps};
opening() = Surface In BoundingBox{-eps, zc - D / 2 + t - eps, -eps, D / 2 - t + eps, zc + D / 2 - t + eps, eps};
drop() = Surface{:};
drop() -= keep();
drop() += opening();
Recursive Delete { Surface{drop()}; }
section() = Surface{:};
Field[1] = MathEval;     // h within the ring (the lining and the zone), growing beyond it
If (chimney > 0)         // the distance from the zone: the ring's, or the chimney's (|x| - chimney above the axis)
  Field[1].F = Sprintf("%g + (%g - %g) * Min(1, Min(Max(0, Sqrt(x^2 + (z - %g)^2) - %g), Max(0, Max(Fabs(x) - %g, %g - z))) / %g)", h, h_far, h, zc, D / 2 + a, chimney, zc, grow);
Else
  Field[1].F = Sprintf("%g + (%g - %g) * Min(1, Max(0, Sqrt(x^2 + (z - %g)^2) - %g) / %g)", h, h_far, h, zc, D / 2 + a, grow);  // meshed after the rotation: x-z
EndIf
Background Field = 1;
Mesh.MeshSizeMin = 0.5 * h;
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{section()}; }
Extrude {0, Ly, 0} { Surface{section()}; Layers{ Ceil(Ly / h_y) }; }
// volumes, by their extents: the lining and zone rings are recognised by their bounding boxes
ring_lining() = Volume In BoundingBox{-eps, -eps, zc - D / 2 - eps, D / 2 + eps, Ly + eps, zc + D / 2 + eps};
top_zone = (chimney > 0) ? Hg : Min(Hg, zc + D / 2 + a);
ring_zone() = Volume In BoundingBox{-eps, -eps, zc - D / 2 - a - eps, Max(D / 2 + a, chimney) + eps, Ly + eps, top_zone + eps};
ring_zone() -= ring_lining();
soil() = Volume{:};
soil() -= ring_zone();
soil() -= ring_lining();
Physical Volume("lining") = {ring_lining()};
Physical Volume("zone") = {ring_zone()};
Physical Volume("soil") = {soil()};
ground() = Surface In BoundingBox{-eps, -eps, Hg - eps, W + eps, Ly + eps, Hg + eps};
If (B > 0)
  strip() = Surface In BoundingBox{-eps, -eps, Hg - eps, B / 2 + eps, Ly + eps, Hg + eps};
  ground() -= strip();
  Physical Surface("strip") = {strip()};
EndIf
Physical Surface("ground") = {ground()};
Physical Surface("base") = Surface In BoundingBox{-eps, -eps, -eps, W + eps, Ly + eps, eps};
Physical Surface("far") = Surface In BoundingBox{W - eps, -eps, -eps, W + eps, Ly + eps, Hg + eps};
Physical Surface("axis") = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly + eps, Hg + eps};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, W + eps, eps, Hg + eps};
sy1() = Surface In BoundingBox{-eps, Ly - eps, -eps, W + eps, Ly + eps, Hg + eps};
Physical Surface("sides") = {sy0(), sy1()};
inner() = Surface In BoundingBox{-eps, -eps, zc - D / 2 + t - eps, D / 2 - t + eps, Ly + eps, zc + D / 2 - t + eps};
inner() -= {sy0(), sy1()};
inner() -= Surface In BoundingBox{-eps, -eps, -eps, eps, Ly + eps, Hg + eps};
Physical Surface("intrados") = {inner()};
