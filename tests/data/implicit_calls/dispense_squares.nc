% dispense_squares
; a program of ours in the style of a dispensing table's CAM output: the maker's cycles are called
; implicitly (G800..G807), M functions with values report progress to the PLC
T1
M200=1200 ; pressure 120 kPa
G803 ; to the safe height
M110=0 ; progress 0 %
G801 ; measure the tool
#CONTOUR MODE ON [DEV PATH_DEV=0.08]
G805[-27.120, 28.955, 2.870] ; the work origin of G55
G55
#FLUSH WAIT
G807[1, 0.002, 0.002] ; start / stop delays [s]
F3000
G00 G55 X-3.000 Y-3.000
Z0.600
M160 ; dispensing on
G01 X3.000
Y3.000
X-3.000
Y-3.000
M161 ; dispensing off
M110=500 ; progress 50 %
G805[-7.820, 28.955, 2.870]
G55
G00 Z18.400
X-3.000
Z0.600
M160
G01 X3.000
Y3.000
M161
G803
V.E.UserInteraction.Message = "Squares done - take the plate, then click OK"
G807 ; delays off
#CONTOUR MODE OFF
M110=1000
G800 ; home
M30
