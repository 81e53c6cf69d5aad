/PROG  PICK_DEMO
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "kinecal test";
PROG_SIZE	= 1024;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 5;
PROTECT		= READ_WRITE;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  UFRAME_NUM=0 ;
   2:  UTOOL_NUM=1 ;
   3:J P[1] 100% FINE    ;
   4:L P[2] 500mm/sec CNT50    ;
   5:J P[3:"above part"] 50% FINE    ;
   6:L P[4] 200mm/sec FINE    ;
/POS
P[1]{
   GP1:
	UF : 0, UT : 1,	
	J1=    10.000 deg,	J2=    20.000 deg,	J3=   -10.000 deg,
	J4=     -.000 deg,	J5=   -65.500 deg,	J6=   120.250 deg
};
P[2]{
   GP1:
	UF : 0, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   450.000  mm,	Y =   -25.000  mm,	Z =   300.000  mm,
	W =  -180.000 deg,	P =      .000 deg,	R =     0.000 deg
};
P[3:"above part"]{
   GP1:
	UF : 0, UT : 1,	
	J1=   -25.125 deg,	J2=    35.000 deg,	J3=     5.000 deg,
	J4=    90.000 deg,	J5=   -80.000 deg,	J6=  -175.500 deg
   GP2:
	UF : 0, UT : 1,	
	J1=   150.000  mm
};
P[4]{
   GP1:
	UF : 0, UT : 1,	
	J1=    40.000 deg,	J2=     5.500 deg,	J3=   -30.000 deg,
	J4=  -100.000 deg,	J5=   -45.000 deg,	J6=     0.000 deg
};
/END
