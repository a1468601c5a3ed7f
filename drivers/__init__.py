"""Device drivers: transports, protocol codecs (plug-ins found by name), stream framers, sessions.

Modules, one job each:
``crc`` catalogue CRCs · ``codec`` the codec interface, frame-batch and raw-chunk records ·
``framing`` byte-stream framer and counter unwrapping · ``kvh1750``, ``xsens``, ``stim300``, ``tts1``,
``can_dbc``, ``acl`` the protocols (``acl``: the Acutrol command language) · ``registry`` the plug-ins of every kind by
name (codecs, controllers, chambers, power supplies) · ``tap`` raw and sample listeners ·
``transport`` pyserial and python-can transports · ``pty_guard`` no reopen onto another program's pty ·
``reader`` reader threads that survive replugs ·
``table_controller`` the turntable controller interface · ``controllers`` the controller and data codec
a ``turntable`` block names · ``can_settings`` an IMU's CAN bus · ``acutrol_controller``, ``aerosmith_controller`` the shipped controllers · ``capture`` decoding of raw captures to CSV.
"""
