// Rectangular block Lx x Ly x Lz with its low corner at (x0, y0, z0), one physical group per face.
// Physical names: volume "solid"; faces "x0", "x1", "y0", "y1", "bottom" (z=z0), "top" (z=z0+Lz).
// The corner's coordinates may be negative (their Min: cosim refuses a negative value of a
// parameter that declares no lower bound, such as the lengths).
SetFactory("OpenCASCADE");
DefineConstant[ Lx = {1.0, Name "Parameters/Lx"}, Ly = {1.0, Name "Parameters/Ly"},
                Lz = {1.0, Name "Parameters/Lz"}, x0 = {0.0, Min -1e6, Name "Parameters/x0"},
                y0 = {0.0, Min -1e6, Name "Parameters/y0"}, z0 = {0.0, Min -1e6, Name "Parameters/z0"} ];
Box(1) = {x0, y0, z0, Lx, Ly, Lz};
eps = 1e-6;
x1 = x0 + Lx; y1 = y0 + Ly; z1 = z0 + Lz;
Physical Volume("solid") = {1};
Physical Surface("x0") = Surface In BoundingBox{x0-eps, y0-eps, z0-eps, x0+eps, y1+eps, z1+eps};
Physical Surface("x1") = Surface In BoundingBox{x1-eps, y0-eps, z0-eps, x1+eps, y1+eps, z1+eps};
Physical Surface("y0") = Surface In BoundingBox{x0-eps, y0-eps, z0-eps, x1+eps, y0+eps, z1+eps};
Physical Surface("y1") = Surface In BoundingBox{x0-eps, y1-eps, z0-eps, x1+eps, y1+eps, z1+eps};
Physical Surface("bottom") = Surface In BoundingBox{x0-eps, y0-eps, z0-eps, x1+eps, y1+eps, z0+eps};
Physical Surface("top") = Surface In BoundingBox{x0-eps, y0-eps, z1-eps, x1+eps, y1+eps, z1+eps};
