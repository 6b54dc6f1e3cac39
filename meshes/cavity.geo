// Rock block W x Ly x H with a circular cavity (tunnel) of radius R along y,
// axis at (x, z) = (W/2, Zc).  Physical names: volume "rock"; faces "cavity"
// (the tunnel wall, where a lining or particles act), "bottom", "top",
// "sides_x" (x=0 and x=W), "ends_y" (y=0 and y=Ly: plane-strain rollers).
SetFactory("OpenCASCADE");
DefineConstant[ W = {4.0, Name "Parameters/W"}, H = {4.0, Name "Parameters/H"},
                Ly = {1.0, Name "Parameters/Ly"}, R = {0.5, Name "Parameters/R"},
                Zc = {2.0, Name "Parameters/Zc"} ];
Box(1) = {0, 0, 0, W, Ly, H};
Cylinder(2) = {W/2, 0, Zc, 0, Ly, 0, R};
BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; }
eps = 1e-6;
Physical Volume("rock") = {1};
Physical Surface("cavity") = Surface In BoundingBox{W/2-R-eps, -eps, Zc-R-eps, W/2+R+eps, Ly+eps, Zc+R+eps};
Physical Surface("bottom") = Surface In BoundingBox{-eps, -eps, -eps, W+eps, Ly+eps, eps};
Physical Surface("top") = Surface In BoundingBox{-eps, -eps, H-eps, W+eps, Ly+eps, H+eps};
sx0() = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly+eps, H+eps};
sx1() = Surface In BoundingBox{W-eps, -eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("sides_x") = {sx0(), sx1()};
ey0() = Surface In BoundingBox{-eps, -eps, -eps, W+eps, eps, H+eps};
ey1() = Surface In BoundingBox{-eps, Ly-eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("ends_y") = {ey0(), ey1()};
