%G803_safe_height
(stand-in: the safe height, 40 mm, in the coordinates in effect)
N10 G90 G00 Z40
N20 M17
