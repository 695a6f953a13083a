"""The example programs of the function descriptions, verbatim, in one place for every test.

FCT-C14 = ../shared/spec/000_41439ccb7b98d127.txt, the older excerpt = 001_d0bd7dabf403e45d.txt.
"""

from __future__ import annotations

U_AREA = """\
N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X-150 Y75 (Startpunkt)
N30 X-50 Y150
N40 X50 Y150
N50 X150 Y75
N60 X150 Y0
N70 X50 Y0
N80 X50 Y75
N90 X-50 Y75
N100 X-50 Y0
N120 X-150 Y0
N130 X-150 Y75 (Endpunkt identisch mit Startpunkt)
N140 #CONTROL AREA END
"""
"""FCT-C14 3.1.1, the U-shaped polygonal work area (BEGIN)."""

U_AREA_START = U_AREA.replace("BEGIN", "START")
"""The same with the older keyword START (the excerpt 001)."""

CIRC_PROT = """\
N10 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X0 Y0 F10000      (Startpunkt für zylindrischen Schutzraum)
N30 G02 G162 I0 J75      ( Definition des Vollkreises)
N40 #CONTROL AREA END
"""
"""FCT-C14 3.1.2, the cylindrical protection area: centre (0, 75), radius 75."""

CIRC_PROT_OLD = """\
N10 #CONTROL AREA START [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X100 Y0 F10000 (Startpunkt für zylindrischen Schutzraum)
N30 G02 G162 I50 J0
N40 #CONTROL AREA END
"""
"""The excerpt 001's circle: centre (150, 0), radius 50."""

EXTRA_AXES_AREA = """\
N10 #CONTROL AREA BEGIN [ID4 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X2=100 Y2=100 ;Startpunkt
N30 X2=-100
N40 Y2=-100
N50 X2=100
N60 X2=100 Y2=100 ;Endpunkt identisch mit Startpunkt
N70 #CONTROL AREA END
"""
"""FCT-C14 section 4: a work area for the additional axes X2, Y2 (height Z2)."""

EXTRA_AXES_PROGRAM = ":\n" + EXTRA_AXES_AREA + ":\nN500 #CONTROL AREA ON ALL\n:\nN1000 M30\n"
"""FCT-C14 section 4 as printed, with its ':' elision lines."""

TWO_PATH_AREA = """\
N040 #CONTROL AREA START [ID=1 WORK MONITOR_LVL = "IMCS" POLY MIN_EXCUR
= -100 MAX_EXCUR = 100]
N050 : G0 X200 Y0 : G0 U150 V0
N060 : G0 X200 Y200 : G0 U150 V150
N070 : G0 X-200 Y200 : G0 U-150 V150
N080 : G0 X-200 Y-200 : G0 U-150 V-150
N090 : G0 X200 Y-200 : G0 U150 V-150
N100 : G0 X200 Y0 : G0 U150 V0
N110 #CONTROL AREA END
"""
"""FCT-C14 2.4, the two-path work area (IMCS), with the document's line wrap."""

SELECT_EXAMPLES = """\
#CONTROL AREA ON [ID3] (Aktiviere spezifischen Ü.-raum)
#CONTROL AREA ON ALL (Aktiviere alle definierten Ü.-räume)
#CONTROL AREA OFF [ID3] (Deaktiviere spezifischen Ü.-raum)
#CONTROL AREA OFF (Deaktiviere zuletzt angewählten Ü.-raum)
#CONTROL AREA OFF ALL (Deaktiviere alle aktiven Ü.-räume)
#CONTROL AREA CLEAR [ID3]
#CONTROL AREA CLEAR ALL
"""
"""FCT-C14 3.2-3.4, the ON / OFF / CLEAR examples."""
