program harness;

{ Runs simtwo/control.pas, included unchanged, against the stand-in API of simtwo_api.pas:
  Initialize once, then Control once per HARNESS-TICK datagram, as SimTwo calls them every script
  period. See simtwo_api.pas for the options and tests/test_simtwo_pascal.py for the checks.
  Build (from any directory):
    fpc -Mdelphi -Fu<repo>/simtwo/test -Fi<repo>/simtwo -FU<out> -FE<out> <repo>/simtwo/test/harness.pas }

{$mode delphi}{$H+}

uses SysUtils, Classes, simtwo_api;

{$I control.pas}

var
  HK, HN: integer;
  HT0: QWord;

procedure RecordSettings;
begin
  HarnessRec('CFG BridgeIP ' + CfgBridgeIP);
  HarnessRec('CFG BridgePort ' + IntToStr(CfgBridgePort));
  HarnessRec('CFG Lockstep ' + IntToStr(CfgLockstep));
  HarnessRec('CFG LockstepWaitMs ' + IntToStr(CfgLockstepWaitMs));
  HarnessRec('CFG CommandTimeoutMs ' + IntToStr(CfgCommandTimeoutMs));
  HarnessRec('CFG LidarNoiseA ' + HarnessReal(CfgLidarNoiseA));
  HarnessRec('CFG LidarNoiseB ' + HarnessReal(CfgLidarNoiseB));
end;

begin
  try
    HarnessStart;
    HarnessWaitTick;
    HCycle := -1;
    Initialize;
    RecordSettings;
    // the test's settings (as a user would edit the constants at the top of control.pas)
    if HarnessHas('bridge_ip') then CfgBridgeIP := HarnessOpt('bridge_ip', '');
    if HarnessHas('bridge_port') then CfgBridgePort := StrToInt(HarnessOpt('bridge_port', ''));
    if HarnessHas('lockstep') then CfgLockstep := StrToInt(HarnessOpt('lockstep', ''));
    if HarnessHas('wait_ms') then CfgLockstepWaitMs := StrToInt(HarnessOpt('wait_ms', ''));
    if HarnessHas('timeout_ms') then CfgCommandTimeoutMs := StrToInt(HarnessOpt('timeout_ms', ''));
    if HarnessHas('noise_a') then CfgLidarNoiseA := HarnessOptReal('noise_a', 0);
    RecordSettings;
    HN := StrToInt(HarnessOpt('cycles', '10'));
    for HK := 0 to HN - 1 do begin
      if HK > 0 then HarnessWaitTick;
      HCycle := HK;
      HarnessRec(Format('CYCLE %d BEGIN', [HK]));
      HT0 := GetTickCount64;
      Control;
      HarnessRec(Format('CYCLE %d END %d', [HK, GetTickCount64 - HT0]));
    end;
    HarnessFinish;
  except
    on E: Exception do begin
      HarnessRec(Format('EXCEPTION %d %s: %s', [HCycle, E.ClassName, E.Message]));
      HarnessFinish;
      Halt(3);
    end;
  end;
end.
