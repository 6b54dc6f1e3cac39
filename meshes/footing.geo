// Square footing plate resting on a soil block, meshed conformally.
// Soil: B x B x D (top at z=0); plate: b x b x t centred on the soil top.
// Physical names: volumes "soil", "footing"; faces "interface" (plate underside =
// soil under the plate), "footing_top", "soil_top" (free soil surface around the
// plate), "soil_bottom", "soil_sides".
SetFactory("OpenCASCADE");
DefineConstant[ B = {2.0, Name "Parameters/B"}, D = {1.0, Name "Parameters/D"},
                b = {0.5, Name "Parameters/b"}, t = {0.1, Name "Parameters/t"} ];
Box(1) = {-B/2, -B/2, -D, B, B, D};
Box(2) = {-b/2, -b/2, 0, b, b, t};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
eps = 1e-6;
vs() = Volume In BoundingBox{-B/2-eps, -B/2-eps, -D-eps, B/2+eps, B/2+eps, eps};
vf() = Volume In BoundingBox{-b/2-eps, -b/2-eps, -eps, b/2+eps, b/2+eps, t+eps};
Physical Volume("soil") = {vs()};
Physical Volume("footing") = {vf()};
Physical Surface("interface") = Surface In BoundingBox{-b/2-eps, -b/2-eps, -eps, b/2+eps, b/2+eps, eps};
Physical Surface("footing_top") = Surface In BoundingBox{-b/2-eps, -b/2-eps, t-eps, b/2+eps, b/2+eps, t+eps};
top() = Surface In BoundingBox{-B/2-eps, -B/2-eps, -eps, B/2+eps, B/2+eps, eps};
Physical Surface("soil_top") = {top()};
Physical Surface("soil_top") -= Surface In BoundingBox{-b/2-eps, -b/2-eps, -eps, b/2+eps, b/2+eps, eps};
Physical Surface("soil_bottom") = Surface In BoundingBox{-B/2-eps, -B/2-eps, -D-eps, B/2+eps, B/2+eps, -D+eps};
sx0() = Surface In BoundingBox{-B/2-eps, -B/2-eps, -D-eps, -B/2+eps, B/2+eps, eps};
sx1() = Surface In BoundingBox{B/2-eps, -B/2-eps, -D-eps, B/2+eps, B/2+eps, eps};
sy0() = Surface In BoundingBox{-B/2-eps, -B/2-eps, -D-eps, B/2+eps, -B/2+eps, eps};
sy1() = Surface In BoundingBox{-B/2-eps, B/2-eps, -D-eps, B/2+eps, B/2+eps, eps};
Physical Surface("soil_sides") = {sx0(), sx1(), sy0(), sy1()};
