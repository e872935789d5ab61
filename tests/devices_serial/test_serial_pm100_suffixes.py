"""PM100 emulator: SCPI unit suffixes on numeric parameters (`633NM`, `633 nm`, `1.5 uW`)
and numbered keywords (`SENS1:...`, `MEAS1:POW?`), over a real pty through the driver."""

import pytest

from drivers.base import DeviceError


@pytest.mark.parametrize(
    "message, nm",
    [
        ("SENS:CORR:WAV 633NM", 633.0),
        ("SENS:CORR:WAV 633 nm", 633.0),
        ("sens:corr:wav 633nm", 633.0),
        ("SENS:CORR:WAV 6.33E2 NM", 633.0),
        ("SENS:CORR:WAV 0.6328UM", 632.8),
        ("SENS:CORR:WAV .85 um", 850.0),
        ("SENS1:CORR:WAV 633", 633.0),
        ("SENSE1:CORRECTION:WAVELENGTH 780 NM", 780.0),
        ("CORR:WAV 905nm", 905.0),
    ],
)
def test_wavelength_with_units_and_numbered_sense(pm_pair, message, nm):
    emu, pm = pm_pair()
    assert pm.query(message) == []
    assert emu.wavelength_nm == pytest.approx(nm, rel=1e-12)
    assert pm.wavelength_nm == pytest.approx(nm, rel=1e-12)


@pytest.mark.parametrize(
    "argument, full_scale_w",
    [("1E-6", 1e-6), ("1E-6W", 1e-6), ("1 uW", 1e-6), ("0.9UW", 1e-6), ("1.5 mW", 1e-2),
     ("100 NW", 1e-6), ("1u", 1e-6), ("5M", 1e-2), ("2e5 pw", 1e-6)],
)
def test_power_range_with_si_units(pm_pair, argument, full_scale_w):
    """SCPI reads M as milli (1.5 mW), bare multipliers too (1u = 1 uW); the emulator's
    ranges are decades from 1 uW, a value picks the smallest full scale holding it."""
    emu, pm = pm_pair()
    pm.query(f"SENS1:POW:RANG {argument}")
    assert pm.range_w == pytest.approx(full_scale_w)
    assert emu.range_w == pytest.approx(full_scale_w) and not emu.autorange


def test_numbered_measurement_keywords(pm_pair):
    emu, pm = pm_pair(power_w=3e-6)
    meas1, read1 = (float(v) for v in pm.query("MEAS1:POW?;:READ1?"))
    assert meas1 == pytest.approx(3e-6, rel=0.05) and read1 == pytest.approx(3e-6, rel=0.05)
    pm.query("CONF1:POW;:INIT1")
    assert float(pm.query("FETC1?")[0]) == pytest.approx(3e-6, rel=0.05)
    assert pm.query("CONF1?") == ["POW"]
    assert pm.query("SENS1:AVER:COUN 4;COUN?") == ["4"]
    assert pm.query("SENS1:CORR:WAV 700NM;WAV?") == ["7.000000E+02"]  # path keeps SENS1


@pytest.mark.parametrize(
    "message, code",
    [
        ("SENS2:CORR:WAV 633", -114),  # one sensor channel: only suffix 1
        ("MEAS0:POW?", -114),
        ("SENS:CORR1:WAV 633", -113),  # CORRection takes no suffix
        ("SYST1:ERR?", -113),
        ("*IDN1?", -113),
        ("SENS1X:CORR:WAV 633", -113),
        ("SENS:CORR:WAV 633KG", -131),  # not a length unit
        ("SENS:CORR:WAV 633W", -131),
        ("SENS:CORR:WAV 633 N", -131),  # a bare multiplier is no wavelength unit
        ("SENS:POW:RANG 1 NM", -131),
        ("SENS:AVER:COUN 4 NM", -138),  # a count takes no suffix
        ("SENS:CORR:WAV 300NM", -222),  # the unit is applied before the range check
        ("SENS:CORR:WAV 2UM", -222),
        ("SENS:CORR:WAV NM", -104),
    ],
)
def test_suffix_errors(pm_pair, message, code):
    emu, pm = pm_pair()
    with pytest.raises(DeviceError) as err:
        pm.query(message)
    assert err.value.code == code
    assert emu.wavelength_nm == 632.8 and emu.averaging == 1
