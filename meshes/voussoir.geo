// Voussoir of a semicircular arch (intrados radius 1 m, ring depth 0.3 m, 15 voussoirs), centred on angle 0.
// Physical curves name the faces; fem_blocks meshes it with `geometry = "file"`.
ri = 1.0;  re = 1.3;  a = Pi / 30;   // half opening angle
lc = 0.05;
Point(1) = {0, 0, 0, lc};
Point(2) = {ri * Cos(-a), ri * Sin(-a), 0, lc};
Point(3) = {re * Cos(-a), re * Sin(-a), 0, lc};
Point(4) = {re * Cos(a), re * Sin(a), 0, lc};
Point(5) = {ri * Cos(a), ri * Sin(a), 0, lc};
Line(1) = {2, 3};
Circle(2) = {3, 1, 4};
Line(3) = {4, 5};
Circle(4) = {5, 1, 2};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Physical Curve("joint_lower") = {1};
Physical Curve("extrados") = {2};
Physical Curve("joint_upper") = {3};
Physical Curve("intrados") = {4};
Physical Surface("voussoir") = {1};
