%G800_home
(stand-in: the table home, in machine coordinates, Z first)
N10 G90 G53 G00 Z100
N20 X0 Y0
N30 M17
