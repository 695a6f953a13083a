; pick_and_teach.nc - a robot program of our own for the stand-in machine (tests/data/robot/README.md):
; start-up subroutine, a pick and place cycle, then the reached pose written to the teach file.
%pick_and_teach
N010 L robot_start.nc
N020 #FILENAME [MSG=V.E.TEACH_FILE_NAME]
N030 G00 G90 X400 Y0 Z600 A0 B90 C0
N040 G01 F30000 X500 Y-200 Z300
N050 Z250 C45
N060 G01 Z300
N070 X300 Y250 Z350 A10 B80 C-30
; where the robot is now, written as a block the teach-in can run again
N080 #CHANNEL INIT [CMDPOS]
N090 $IF V.E.TEACH_ACS == 1
N100   #MSG SAVE EXCLUSIVE ["G01 G90 F1000 X=%.3f Y=%.3f Z=%.3f A=%.3f B=%.3f C=%.3f", V.A.ABS.X, V.A.ABS.Y, V.A.ABS.Z, V.A.ABS.A, V.A.ABS.B, V.A.ABS.C]
N110 $ELSE
N120   #MSG SAVE EXCLUSIVE ["G01 G90 F5000 X=%.3f Y=%.3f Z=%.3f", V.A.ABS.X, V.A.ABS.Y, V.A.ABS.Z]
N130 $ENDIF
N140 #VECTOR LIMIT OFF ALL
N150 M30
