// robotatfactory: field_dump.pas - a SimTwo scene script (PascalScript, as SimTwo compiles it) that reads back
// what SimTwo built for the RobotFactoryPro2022 scene, for the comparison with the project's field model
// (raf simtwo field, src/robotatfactory/simtwo_linux/fielddump.py, tests/test_simtwo_field.py).
// Run it as the control script of a fresh copy of the scene (robot 'AGV' with the project's LIDAR).
//
// Output, one line each (numbers in SimTwo's world frame: metres, radians):
//   FIELD start
//   FIELD robot0 <ID> <index> <x> <y> <z> <theta>         the robots (AGV, Part1..Part4) in Initialize, as the
//                                                         scene placed them
//   FIELD robot <ID> <index> <x> <y> <z> <theta>          the same at the first Control (after the first steps)
//   FIELD obstacle <index> <x> <y> <z> <R00> <R01> <R02> <R10> ... <R22> <red> <green> <blue>
//                                                         every obstacle SimTwo built: the centre and rotation
//                                                         matrix of its ODE geometry (world <- obstacle)
//   FIELD obstacles <count>
//   FIELD name <ID> <index>                                the index of each obstacle ID the scene's files give
//   FIELD slot <name> <x> <y> <theta> <x0> <y0> <theta0>   a part set down at a slot (x0 y0 theta0, SetRobotPos)
//                                                         and where it stands PROBE_SETTLE cycles later
//   FIELD lidar <name> <x> <y> <theta> <n> <r0>;<r1>;...   the LIDAR's sweep with the robot set down there
//                                                         (its pose as SimTwo reads it at the sweep)
//   FIELD camera <name> <x> <y> <theta>                    the robot stands there until a datagram
//                                                         'FIELD next <name>' arrives on SimTwo's UDP port
//                                                         (fielddump.py sends it once it holds a frame
//                                                         rendered after the line; a software-rendered
//                                                         camera gives about one a second) or CAMERA_HOLD
//                                                         cycles have passed
//   FIELD done
//
// SimTwo's script API has no obstacle count, ID or size getter: the obstacles are read by index until the
// index is out of range, their IDs looked up with GetObstacleIndex, and their sizes measured with the LIDAR
// (the faces its rays meet) and with parts set down in the slots (a wall or rib where the model has none
// pushes the part away). The slot and LIDAR probes are the block between BEGIN PROBES and END PROBES, which
// fielddump.py rewrites from the field model; the block below is simtwo2022's.

const
  PROBE_SETTLE = 12;     // cycles a probe waits (0.48 s at 40 ms: two LIDAR periods of 0.2 s, a part at rest)
  CAMERA_HOLD = 500;     // cycles the robot stands still at most after its camera line (20 s), waiting for
                         // 'FIELD next <name>' from fielddump.py
  PART_Z = 0.0021;       // scene.xml part_pos_z
  SPARE_X = 3.0;         // parts wait off the field, beyond every wall, at (SPARE_X, SPARE_Y + 0.2 i)
  SPARE_Y = 3.0;

var
  Cycle, Phase, ProbeIndex, ProbeWait: integer;
  RAGV, RProbe, ILidar: integer;
  PX, PY, PTh: double;
  PName, Heard, Dropped: string;
  Done: boolean;

function F(x: double): string;
begin
  result := Format('%.6f', [x]);
end;

// ---------------------------------------------------------------------------------------------- the scene

procedure DumpRobot(kind, id: string);
var r: integer;
begin
  r := GetRobotIndex(id);
  if r < 0 then begin
    WriteLn('FIELD ' + kind + ' ' + id + ' -1');
    exit;
  end;
  WriteLn('FIELD ' + kind + ' ' + id + ' ' + IntToStr(r) + ' ' + F(GetRobotX(r)) + ' ' + F(GetRobotY(r)) + ' ' +
          F(GetSolidZ(r, 0)) + ' ' + F(GetRobotTheta(r)));
end;

procedure DumpObstacles;
var i, r, c: integer;
    p: TPoint3D;
    M: Matrix;
    col: TRGBAColor;
    s: string;
    more: boolean;
begin
  i := 0;
  more := true;
  while more do begin
    try
      p := GetObstaclePos(i);
      M := GetObstacleRotMat(i);
      col := GetObstacleColor(i);
      s := 'FIELD obstacle ' + IntToStr(i) + ' ' + F(p.x) + ' ' + F(p.y) + ' ' + F(p.z);
      for r := 0 to 2 do begin
        for c := 0 to 2 do begin
          s := s + ' ' + F(Mgetv(M, r, c));
        end;
      end;
      WriteLn(s + ' ' + IntToStr(col.Red) + ' ' + IntToStr(col.Green) + ' ' + IntToStr(col.Blue));
      i := i + 1;
    except
      more := false;  // list index out of bounds: that was the last one
    end;
    if i > 10000 then more := false;
  end;
  WriteLn('FIELD obstacles ' + IntToStr(i));
end;

procedure DumpName(id: string);
begin
  WriteLn('FIELD name ' + id + ' ' + IntToStr(GetObstacleIndex(id)));
end;

// the obstacle IDs of RobotFactoryPro2022: scene.xml's <obstacle> ID followed by the cuboid's ID in its file
procedure DumpNames;
var w, m, j: integer;
    prefix: string;
begin
  DumpName('fieldfield_pro');
  for w := 0 to 1 do begin
    if w = 0 then prefix := 'incoming_whareouse_' else prefix := 'output_whareouse_';
    DumpName(prefix + 'right_wall');
    DumpName(prefix + 'left_wall');
    DumpName(prefix + 'back_wall');
    DumpName(prefix + 'back_wall_marker');
    for j := 1 to 4 do DumpName(prefix + 'back_wall_marker_' + IntToStr(j));
    for j := 1 to 3 do DumpName(prefix + 'inside_wall_' + IntToStr(j));
  end;
  for m := 0 to 1 do begin
    if m = 0 then prefix := 'Machines_A_' else prefix := 'Machines_B_';
    DumpName(prefix + 'left_wall');
    DumpName(prefix + 'center_wall');
    DumpName(prefix + 'right_wall');
    DumpName(prefix + 'back_wall');
    DumpName(prefix + 'back_wall_marker_support');
    DumpName(prefix + 'back_wall_marker_BR');
    DumpName(prefix + 'back_wall_marker_TR');
    DumpName(prefix + 'back_wall_marker_BL');
    DumpName(prefix + 'back_wall_marker_TL');
  end;
end;

procedure PartsAway;
var i, r: integer;
begin
  for i := 1 to 4 do begin
    r := GetRobotIndex('Part' + IntToStr(i));
    if r >= 0 then SetRobotPos(r, SPARE_X, SPARE_Y + 0.2 * i, PART_Z, 0);
  end;
end;

// ---------------------------------------------------------------------------------------------- probes
// SetProbe(k) describes probe k (0-based): kind 0 = a part set down at a slot, 1 = the robot set down for a
// LIDAR sweep; PName, PX, PY, PTh its name and pose. ProbeCount: how many.

// BEGIN PROBES
function ProbeCount: integer;
begin
  result := 0;
end;

function SetProbe(n: integer): integer;
begin
  result := 0;
end;
// END PROBES

procedure StartProbe;
var kind: integer;
begin
  kind := SetProbe(ProbeIndex);
  if kind = 0 then begin
    RProbe := GetRobotIndex('Part1');
    SetRobotPos(RProbe, PX, PY, PART_Z, PTh);
  end else begin
    RProbe := RAGV;
    SetRobotPos(RAGV, PX, PY, 0, PTh);
  end;
  ProbeWait := PROBE_SETTLE;
end;

function EndProbe: integer;
var kind, i, n: integer;
    M: Matrix;
    s: string;
begin
  kind := SetProbe(ProbeIndex);
  if kind = 0 then begin
    WriteLn('FIELD slot ' + PName + ' ' + F(GetRobotX(RProbe)) + ' ' + F(GetRobotY(RProbe)) + ' ' +
            F(GetRobotTheta(RProbe)) + ' ' + F(PX) + ' ' + F(PY) + ' ' + F(PTh));
    SetRobotPos(RProbe, SPARE_X, SPARE_Y + 0.2, PART_Z, 0);
  end else begin
    s := '';
    n := 0;
    if ILidar >= 0 then begin
      M := GetSensorValues(RAGV, ILidar);
      n := MNumRows(M);
      for i := 0 to n - 1 do begin
        if i > 0 then s := s + ';';
        s := s + Format('%.5f', [Mgetv(M, i, 0)]);
      end;
    end;
    WriteLn('FIELD lidar ' + PName + ' ' + F(GetRobotX(RAGV)) + ' ' + F(GetRobotY(RAGV)) + ' ' +
            F(GetRobotTheta(RAGV)) + ' ' + IntToStr(n) + ' ' + s);
    WriteLn('FIELD camera ' + PName + ' ' + F(GetRobotX(RAGV)) + ' ' + F(GetRobotY(RAGV)) + ' ' +
            F(GetRobotTheta(RAGV)));
  end;
  result := kind;
end;

// ---------------------------------------------------------------------------------------------- main

procedure DumpRobots(kind: string);
begin
  DumpRobot(kind, 'AGV');
  DumpRobot(kind, 'Part1');
  DumpRobot(kind, 'Part2');
  DumpRobot(kind, 'Part3');
  DumpRobot(kind, 'Part4');
end;

procedure Initialize;
begin
  Cycle := 0;
  Phase := 0;
  Done := false;
  RAGV := GetRobotIndex('AGV');
  ILidar := -1;
  if RAGV >= 0 then ILidar := GetSensorIndex(RAGV, 'ranger2d');
  WriteLn('FIELD start');
  DumpRobots('robot0');
end;

procedure Control;
begin
  if Done then exit;
  Cycle := Cycle + 1;
  if Phase = 0 then begin
    DumpRobots('robot');
    DumpObstacles;
    DumpNames;
    PartsAway;
    ProbeIndex := 0;
    Phase := 1;
    ProbeWait := 2;  // the parts leave first
    exit;
  end;
  Heard := ReadUDPData();        // SimTwo keeps each datagram twice: here, and in the packet list
  while GetUDPPacketCount() > 0 do Dropped := ReadUDPPacket();
  if (Phase = 3) and (Pos('FIELD next ' + PName + ';', Heard) > 0) then ProbeWait := 1;
  ProbeWait := ProbeWait - 1;
  if ProbeWait > 0 then exit;
  if Phase = 2 then begin
    if EndProbe = 1 then begin
      Phase := 3;                // the robot stands still for the camera
      ProbeWait := CAMERA_HOLD;
      exit;
    end;
    ProbeIndex := ProbeIndex + 1;
  end;
  if Phase = 3 then ProbeIndex := ProbeIndex + 1;
  if ProbeIndex < ProbeCount then begin
    StartProbe;
    Phase := 2;
  end else begin
    WriteLn('FIELD done');
    Done := true;
  end;
end;
