"""The committed FMUs, wherever the package is: installed from a wheel or run from a clone.

A wheel carries ``fmus/PiezoImpactDamper.fmu`` (FMI 2.0, co-simulation) and
``fmus/PiezoImpactDamper3.fmu`` (FMI 3.0, co-simulation and Model Exchange) as package data, in
``piezo_fmu_harness/fmu_files/``. A clone (or an editable install of it) has them in the
repository's ``fmus/`` folder. :func:`path` returns the one that exists, so that a user, the
harness and a script find the FMU the same way from any working directory.

This module imports nothing but the standard library.
"""

from __future__ import annotations

from pathlib import Path

#: The file name of each FMU, by FMI version.
FILE_NAMES = {2: "PiezoImpactDamper.fmu", 3: "PiezoImpactDamper3.fmu"}

#: Where a wheel puts the FMUs (package data), and where a clone has them.
_FOLDERS = (Path(__file__).resolve().parent / "fmu_files",
            Path(__file__).resolve().parents[2] / "fmus")


def path(fmi_version: int = 2) -> Path:
    """The path of the piezo-impact damper FMU of one FMI version.

    Parameters
    ----------
    fmi_version : int, optional
        2 for the FMI 2.0 co-simulation FMU (the default, the one the harness runs), 3 for the
        FMI 3.0 FMU that offers co-simulation and Model Exchange.

    Returns
    -------
    pathlib.Path
        The absolute path of the ``.fmu`` file: the package data of an installed wheel, else the
        ``fmus/`` folder of the clone the package is imported from.

    Raises
    ------
    ValueError
        If ``fmi_version`` is neither 2 nor 3.
    FileNotFoundError
        If neither place holds the file (an incomplete installation).

    Examples
    --------
    >>> from piezo_fmu_harness import fmus
    >>> fmus.path().name
    'PiezoImpactDamper.fmu'
    >>> fmus.path(fmi_version=3).name
    'PiezoImpactDamper3.fmu'
    """
    if fmi_version not in FILE_NAMES:
        raise ValueError(f"fmi_version = {fmi_version!r} is not an FMI version of this project; "
                         f"allowed values {sorted(FILE_NAMES)}")
    name = FILE_NAMES[fmi_version]
    for folder in _FOLDERS:
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(f"{name} is in none of {', '.join(str(f) for f in _FOLDERS)}; "
                            "reinstall piezo-fmu, or build the FMU with `python -m piezo_fmu.build`")
