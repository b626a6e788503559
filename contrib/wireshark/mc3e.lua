-- MELSEC communication protocol (MC protocol), 3E and 4E frames in binary code, as rackd
-- speaks it to Mitsubishi Q/L PLCs (src/protocols/mc3e, /work/shared/spec/crane-mc3e.md).
--
-- Requests (subheader 50 00, 4E: 54 00 + serial) and responses (D0 00, 4E: D4 00) over TCP
-- and UDP: route, data length, monitoring timer, command and subcommand, devices, points,
-- values; end codes with their meanings. A response's data is read with its request (matched
-- by connection, and by serial number for 4E), so read words show under their device
-- numbers, and with the crane's register names when that preference is on.
--
-- Registered on a TCP and UDP port (preference, default 8000: rackd's example crane port;
-- MC has no assigned port) and as a heuristic on TCP and UDP (first bytes and length field).
-- Filter fields: mc3e.* (mc3e.command, mc3e.end_code, mc3e.device_code, mc3e.head,
-- mc3e.points, mc3e.word, mc3e.register, ...).

local mc3e = Proto("mc3e", "MELSEC MC Protocol (3E/4E binary)")

local commands = {
    [0x0401] = "Batch read",
    [0x1401] = "Batch write",
    [0x0101] = "Read CPU model name",
    [0x0403] = "Random read (words)",
    [0x0406] = "Multiple-block batch read",
    [0x1402] = "Random write",
    [0x1406] = "Multiple-block batch write",
    [0x0801] = "Monitor registration",
    [0x0802] = "Monitor",
    [0x1001] = "Remote RUN",
    [0x1002] = "Remote STOP",
    [0x1003] = "Remote PAUSE",
    [0x1005] = "Remote latch clear",
    [0x1006] = "Remote RESET",
    [0x0619] = "Loopback test",
}

local subcommands = {
    [0x0000] = "word units",
    [0x0001] = "bit units",
    [0x0002] = "word units (iQ-R device numbers)",
    [0x0003] = "bit units (iQ-R device numbers)",
}

-- Device codes as rackd's codec knows them (src/protocols/mc3e/device.rs); hex marks the
-- devices numbered in hexadecimal, bit the bit devices.
local devices = {
    [0xA8] = { name = "D" }, [0xB4] = { name = "W", hex = true }, [0xAF] = { name = "R" },
    [0xB0] = { name = "ZR" }, [0xA9] = { name = "SD" }, [0xB5] = { name = "SW", hex = true },
    [0xC2] = { name = "TN" }, [0xC8] = { name = "STN" }, [0xC5] = { name = "CN" },
    [0x90] = { name = "M", bit = true }, [0x9C] = { name = "X", hex = true, bit = true },
    [0x9D] = { name = "Y", hex = true, bit = true }, [0xA0] = { name = "B", hex = true, bit = true },
    [0x92] = { name = "L", bit = true }, [0x91] = { name = "SM", bit = true },
    [0x93] = { name = "F", bit = true }, [0x94] = { name = "V", bit = true },
    [0xA1] = { name = "SB", hex = true, bit = true }, [0xC1] = { name = "TS", bit = true },
    [0xC0] = { name = "TC", bit = true }, [0xC7] = { name = "STS", bit = true },
    [0xC6] = { name = "STC", bit = true }, [0xC4] = { name = "CS", bit = true },
    [0xC3] = { name = "CC", bit = true },
}
local device_names = {}
for code, d in pairs(devices) do device_names[code] = d.name end

-- End code meanings, as src/protocols/mc3e/end_code.rs words them.
local function end_code_meaning(code)
    local fixed = {
        [0x0000] = "normal completion",
        [0xC050] = "ASCII code data that cannot be converted to binary was received",
        [0xC055] = "the number of file data read/write points is outside the allowed range",
        [0xC056] = "the read/write request exceeds the largest device number",
        [0xC057] = "the request data length does not match the data in the request (file data)",
        [0xC058] = "the request data length after ASCII-to-binary conversion does not match the data",
        [0xC059] = "wrong command or subcommand, or a command the target cannot execute",
        [0xC05A] = "the target cannot read or write the specified device",
        [0xC05B] = "the target cannot read or write the specified device",
        [0xC05C] = "error in the request contents (e.g. bit-unit access to a word device)",
        [0xC05D] = "monitor registration has not been made",
        [0xC05E] = "the communication time with the CPU exceeded the monitoring timer",
        [0xC05F] = "the request cannot be executed by the target CPU module",
        [0xC060] = "error in the request data (e.g. bit data other than 0 or 1)",
        [0xC061] = "the request data length does not match the number of data",
        [0xC06F] = "communication data code mismatch (ASCII request to a binary port or vice versa)",
        [0xC070] = "device memory extension cannot be specified for the target station",
        [0xC072] = "error in the request contents for the target (e.g. unsupported word-unit access)",
        [0xC074] = "the target CPU cannot execute the request (e.g. wrong network number)",
    }
    if fixed[code] then return fixed[code] end
    if code >= 0xC051 and code <= 0xC054 then
        return "the number of read/write points is outside the allowed range"
    end
    if code >= 0x4000 and code <= 0x4FFF then
        return "error detected by the CPU module (see the CPU's error code list)"
    end
    return "unknown end code (see the PLC's or Ethernet module's manual)"
end

-- The crane's register interface (spec crane-mc3e.md), by offset from each block's base.
local wcs_names = {
    [0] = "heartbeat", [8] = "task number", [9] = "mode", [10] = "from row", [11] = "from bay",
    [12] = "from level", [13] = "from side", [14] = "to row", [15] = "to bay", [16] = "to level",
    [17] = "to side", [20] = "execute action", [21] = "STB", [22] = "task completion acknowledged",
}
local crane_names = {
    [0] = "heartbeat", [1] = "crane status", [2] = "crane scheduling status",
    [3] = "current action state", [5] = "alarm code", [6] = "load on the platform",
    [8] = "task number (echo)", [9] = "mode (echo)", [10] = "from row (echo)",
    [11] = "from bay (echo)", [12] = "from level (echo)", [13] = "from side (echo)",
    [14] = "to row (echo)", [15] = "to bay (echo)", [16] = "to level (echo)",
    [17] = "to side (echo)", [20] = "travel axis position", [21] = "lift axis position",
    [23] = "task completion state", [24] = "load height check state", [25] = "ACK",
}

mc3e.prefs.port = Pref.uint("TCP and UDP port", 8000, "The port the PLC's Ethernet module listens on")
mc3e.prefs.heuristic = Pref.bool("Find MC frames on any port", true,
    "Try frames on other TCP and UDP ports by their subheader and length field")
mc3e.prefs.crane_names = Pref.bool("Name the crane's registers", true,
    "Show D registers of the crane interface with their names (crane-mc3e.md)")
mc3e.prefs.wcs_base = Pref.uint("WCS block base (D)", 0, "First D register rackd writes (wcs_base)")
mc3e.prefs.crane_base = Pref.uint("Crane block base (D)", 200, "First D register the crane writes (crane_base)")

local f = {
    subheader = ProtoField.uint16("mc3e.subheader", "Subheader", base.HEX),
    frame = ProtoField.string("mc3e.frame", "Frame"),
    response = ProtoField.bool("mc3e.response", "Response"),
    serial = ProtoField.uint16("mc3e.serial", "Serial number", base.DEC),
    network = ProtoField.uint8("mc3e.network", "Network number", base.DEC),
    pc = ProtoField.uint8("mc3e.pc", "PC number", base.HEX),
    module_io = ProtoField.uint16("mc3e.module_io", "Request destination module I/O", base.HEX),
    station = ProtoField.uint8("mc3e.station", "Request destination module station", base.DEC),
    length = ProtoField.uint16("mc3e.length", "Data length", base.DEC),
    timer = ProtoField.uint16("mc3e.timer", "Monitoring timer (x 250 ms)", base.DEC),
    command = ProtoField.uint16("mc3e.command", "Command", base.HEX, commands),
    subcommand = ProtoField.uint16("mc3e.subcommand", "Subcommand", base.HEX, subcommands),
    device_code = ProtoField.uint8("mc3e.device_code", "Device code", base.HEX, device_names),
    device = ProtoField.string("mc3e.device", "Device"),
    head = ProtoField.uint32("mc3e.head", "Head device number", base.DEC),
    points = ProtoField.uint16("mc3e.points", "Number of points", base.DEC),
    word_points = ProtoField.uint8("mc3e.word_points", "Word access points", base.DEC),
    dword_points = ProtoField.uint8("mc3e.dword_points", "Double word access points", base.DEC),
    word_blocks = ProtoField.uint8("mc3e.word_blocks", "Word device blocks", base.DEC),
    bit_blocks = ProtoField.uint8("mc3e.bit_blocks", "Bit device blocks", base.DEC),
    word = ProtoField.uint16("mc3e.word", "Word", base.DEC),
    dword = ProtoField.uint32("mc3e.dword", "Double word", base.DEC),
    bit = ProtoField.uint8("mc3e.bit", "Bit", base.DEC),
    register = ProtoField.string("mc3e.register", "Register"),
    end_code = ProtoField.uint16("mc3e.end_code", "End code", base.HEX),
    meaning = ProtoField.string("mc3e.end_code.meaning", "Meaning"),
    model = ProtoField.string("mc3e.model", "CPU model name"),
    model_code = ProtoField.uint16("mc3e.model_code", "CPU model code", base.HEX),
    err_command = ProtoField.uint16("mc3e.error.command", "Failed command", base.HEX, commands),
    err_subcommand = ProtoField.uint16("mc3e.error.subcommand", "Failed subcommand", base.HEX),
    data = ProtoField.bytes("mc3e.data", "Data"),
    request_in = ProtoField.framenum("mc3e.request_in", "Request in frame", base.NONE),
}
mc3e.fields = f

local e = {
    error_end = ProtoExpert.new("mc3e.end_code.error", "The PLC refused the request",
        expert.group.RESPONSE_CODE, expert.severity.WARN),
    length = ProtoExpert.new("mc3e.length.bad", "The data does not fit the frame",
        expert.group.MALFORMED, expert.severity.ERROR),
}
mc3e.experts = { e.error_end, e.length }

-- Requests by connection (and serial), for the responses: first pass fills, later passes read.
local pending = {}
local answers = {}

function mc3e.init()
    pending = {}
    answers = {}
end

local function address(code, number)
    local d = devices[code]
    if not d then return string.format("device %02X %d", code, number) end
    if d.hex then return string.format("%s%X", d.name, number) end
    return d.name .. number
end

local function register_name(code, number)
    if code ~= 0xA8 or not mc3e.prefs.crane_names then return nil end
    local w = number - mc3e.prefs.wcs_base
    local c = number - mc3e.prefs.crane_base
    if w >= 0 and w < 40 then return wcs_names[w] or "reserved" end
    if c >= 0 and c < 40 then return crane_names[c] or "reserved" end
    return nil
end

-- One word at `range` from device `code` number `number`.
local function add_word(tree, range, code, number)
    local value = range:le_uint()
    local label = address(code, number)
    local name = register_name(code, number)
    local item = tree:add_le(f.word, range)
    if name then
        item:set_text(string.format("%s (%s): %d", label, name, value))
        item:add(f.register, string.format("%s %s", label, name)):set_generated()
    else
        item:set_text(string.format("%s: %d (0x%04X)", label, value, value))
        item:add(f.register, label):set_generated()
    end
end

local function add_words(tree, tvb, offset, count, code, head)
    for i = 0, count - 1 do
        if offset + 2 > tvb:len() then return end
        add_word(tree, tvb(offset, 2), code, head + i)
        offset = offset + 2
    end
end

local function add_bits(tree, tvb, offset, count, code, head)
    for i = 0, count - 1 do
        local byte = offset + math.floor(i / 2)
        if byte >= tvb:len() then return end
        local v = tvb(byte, 1):uint()
        local bit = (i % 2 == 0) and math.floor(v / 16) or (v % 16)
        tree:add(f.bit, tvb(byte, 1), bit):set_text(string.format("%s: %d", address(code, head + i), bit))
    end
end

-- device number (3) and code (1) at offset: adds them, returns code, number.
local function add_device(tree, tvb, offset)
    local number = tvb(offset, 3):le_uint()
    local code = tvb(offset + 3, 1):uint()
    tree:add_le(f.head, tvb(offset, 3))
    tree:add(f.device_code, tvb(offset + 3, 1))
    tree:add(f.device, tvb(offset, 4), address(code, number)):set_generated()
    return code, number
end

local function conversation_key(pinfo, response)
    local a = tostring(pinfo.src) .. ":" .. pinfo.src_port
    local b = tostring(pinfo.dst) .. ":" .. pinfo.dst_port
    if response then return b .. ">" .. a end
    return a .. ">" .. b
end

-- The request part after the subcommand; returns what the response needs and an Info text.
local function dissect_request(tvb, offset, stop, tree, command, sub)
    local req = { command = command, sub = sub }
    local remaining = stop - offset
    if (command == 0x0401 or command == 0x1401) and remaining >= 6 then
        local code, head = add_device(tree, tvb, offset)
        local points = tvb(offset + 4, 2):le_uint()
        tree:add_le(f.points, tvb(offset + 4, 2))
        req.code, req.head, req.points = code, head, points
        local kind = (sub % 2 == 1) and "bits" or "words"
        local info = string.format("%s %s %s x%d",
            command == 0x0401 and "read" or "write", kind, address(code, head), points)
        if command == 0x1401 then
            local values = tree:add(f.data, tvb(offset + 6, stop - offset - 6))
            values:set_text("Values")
            if sub % 2 == 1 then
                add_bits(values, tvb, offset + 6, points, code, head)
            else
                add_words(values, tvb, offset + 6, points, code, head)
            end
        end
        return req, info
    elseif command == 0x0403 and remaining >= 2 then
        local w, d = tvb(offset, 1):uint(), tvb(offset + 1, 1):uint()
        tree:add(f.word_points, tvb(offset, 1))
        tree:add(f.dword_points, tvb(offset + 1, 1))
        req.list = {}
        local at = offset + 2
        for i = 1, w + d do
            if at + 4 > stop then break end
            local dev = tree:add(f.data, tvb(at, 4))
            local code, number = add_device(dev, tvb, at)
            dev:set_text((i <= w and "Word " or "Double word ") .. address(code, number))
            req.list[i] = { code = code, number = number, dword = i > w }
            at = at + 4
        end
        return req, string.format("random read %d words, %d double words", w, d)
    elseif command == 0x0406 and remaining >= 2 then
        local w, b = tvb(offset, 1):uint(), tvb(offset + 1, 1):uint()
        tree:add(f.word_blocks, tvb(offset, 1))
        tree:add(f.bit_blocks, tvb(offset + 1, 1))
        req.blocks = {}
        local at = offset + 2
        for i = 1, w + b do
            if at + 6 > stop then break end
            local blk = tree:add(f.data, tvb(at, 6))
            local code, number = add_device(blk, tvb, at)
            local points = tvb(at + 4, 2):le_uint()
            blk:add_le(f.points, tvb(at + 4, 2))
            blk:set_text(string.format("Block %s x%d", address(code, number), points))
            req.blocks[i] = { code = code, number = number, points = points, bits = i > w }
            at = at + 6
        end
        return req, string.format("block read %d word blocks, %d bit blocks", w, b)
    elseif command == 0x0101 then
        return req, "read CPU model name"
    end
    if remaining > 0 then tree:add(f.data, tvb(offset, remaining)) end
    return req, commands[command] or string.format("command %04X", command)
end

-- A normal response's data, read with its request.
local function dissect_answer(tvb, offset, stop, tree, req)
    local remaining = stop - offset
    if remaining <= 0 then return "" end
    local data = tree:add(f.data, tvb(offset, remaining))
    if not req then return "" end
    if req.command == 0x0401 and req.code then
        if req.sub % 2 == 1 then
            add_bits(data, tvb, offset, req.points, req.code, req.head)
            return string.format(" (%d bits)", req.points)
        end
        data:set_text(string.format("Values of %s x%d", address(req.code, req.head), req.points))
        add_words(data, tvb, offset, math.floor(remaining / 2), req.code, req.head)
        return string.format(" (%d words)", math.floor(remaining / 2))
    elseif req.command == 0x0101 and remaining >= 18 then
        local model = tvb(offset, 16):string():gsub("[ %z]+$", "")
        data:add(f.model, tvb(offset, 16), model)
        data:add_le(f.model_code, tvb(offset + 16, 2))
        return " (" .. model .. ")"
    elseif req.command == 0x0403 and req.list then
        local at = offset
        for _, p in ipairs(req.list) do
            if p.dword then
                if at + 4 > stop then break end
                data:add_le(f.dword, tvb(at, 4)):prepend_text(address(p.code, p.number) .. " ")
                at = at + 4
            else
                if at + 2 > stop then break end
                add_word(data, tvb(at, 2), p.code, p.number)
                at = at + 2
            end
        end
    elseif req.command == 0x0406 and req.blocks then
        local at = offset
        for _, b in ipairs(req.blocks) do
            add_words(data, tvb, at, math.min(b.points, math.floor((stop - at) / 2)), b.code, b.number)
            at = at + 2 * b.points
        end
    end
    return ""
end

-- Bytes a frame at `offset` needs: header size and whole length, or nil if not MC.
local function frame_size(tvb, offset)
    local left = tvb:len() - offset
    if left < 2 then return nil, 2 end
    local s = tvb(offset, 2):uint()
    local header
    if s == 0x5000 or s == 0xD000 then header = 9
    elseif s == 0x5400 or s == 0xD400 then header = 13
    else return nil end
    if left < header then return header, header end
    return header, header + tvb(offset + header - 2, 2):le_uint()
end

-- One frame at offset; returns its length.
local function dissect_frame(tvb, pinfo, root, offset, header, total)
    local subheader = tvb(offset, 2):uint()
    local response = subheader == 0xD000 or subheader == 0xD400
    local four = header == 13
    local tree = root:add(mc3e, tvb(offset, math.min(total, tvb:len() - offset)))
    tree:add(f.subheader, tvb(offset, 2))
    tree:add(f.frame, tvb(offset, 2), four and "4E" or "3E"):set_generated()
    tree:add(f.response, tvb(offset, 2), response):set_generated()
    local serial
    if four then
        serial = tvb(offset + 2, 2):le_uint()
        tree:add_le(f.serial, tvb(offset + 2, 2))
    end
    local r = offset + header - 7
    tree:add(f.network, tvb(r, 1))
    tree:add(f.pc, tvb(r + 1, 1))
    tree:add_le(f.module_io, tvb(r + 2, 2))
    tree:add(f.station, tvb(r + 4, 1))
    local length_item = tree:add_le(f.length, tvb(r + 5, 2))
    local stop = offset + total
    if stop > tvb:len() then
        length_item:add_proto_expert_info(e.length)
        stop = tvb:len()
    end
    local at = offset + header
    local key = conversation_key(pinfo, response) .. (serial and ("#" .. serial) or "")
    local kind = four and "4E " or "3E "
    if not response then
        if stop - at < 6 then
            length_item:add_proto_expert_info(e.length)
            return total
        end
        tree:add_le(f.timer, tvb(at, 2))
        local command = tvb(at + 2, 2):le_uint()
        local sub = tvb(at + 4, 2):le_uint()
        tree:add_le(f.command, tvb(at + 2, 2))
        tree:add_le(f.subcommand, tvb(at + 4, 2))
        local req, info = dissect_request(tvb, at + 6, stop, tree, command, sub)
        if not pinfo.visited then
            req.frame = pinfo.number
            pending[key] = req
        end
        pinfo.cols.info:append(kind .. "Request: " .. info .. (serial and (", serial " .. serial) or "") .. "  ")
        return total
    end
    if stop - at < 2 then
        length_item:add_proto_expert_info(e.length)
        return total
    end
    local code = tvb(at, 2):le_uint()
    local code_item = tree:add_le(f.end_code, tvb(at, 2))
    code_item:append_text(" (" .. end_code_meaning(code) .. ")")
    code_item:add(f.meaning, tvb(at, 2), end_code_meaning(code)):set_generated()
    if not pinfo.visited then
        answers[pinfo.number] = pending[key]
        pending[key] = nil
    end
    local req = answers[pinfo.number]
    if req then tree:add(f.request_in, req.frame):set_generated() end
    local info
    if code == 0 then
        info = "end code 0" .. dissect_answer(tvb, at + 2, stop, tree, req)
    else
        code_item:add_proto_expert_info(e.error_end)
        info = string.format("end code %04X: %s", code, end_code_meaning(code))
        if stop - at - 2 == 9 then
            local ei = tree:add(f.data, tvb(at + 2, 9))
            ei:set_text("Error information")
            ei:add(f.network, tvb(at + 2, 1))
            ei:add(f.pc, tvb(at + 3, 1))
            ei:add_le(f.module_io, tvb(at + 4, 2))
            ei:add(f.station, tvb(at + 6, 1))
            ei:add_le(f.err_command, tvb(at + 7, 2))
            ei:add_le(f.err_subcommand, tvb(at + 9, 2))
        elseif stop - at - 2 > 0 then
            tree:add(f.data, tvb(at + 2, stop - at - 2))
        end
    end
    pinfo.cols.info:append(kind .. "Response: " .. info .. (serial and (", serial " .. serial) or "") .. "  ")
    return total
end

function mc3e.dissector(tvb, pinfo, root)
    local offset = 0
    local tcp = pinfo.port_type == 2
    pinfo.cols.protocol = "MC3E"
    pinfo.cols.info:clear()
    while offset < tvb:len() do
        local header, total = frame_size(tvb, offset)
        if not header then
            if total and tcp then
                pinfo.desegment_offset = offset
                pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
                return tvb:len()
            end
            if offset == 0 then return 0 end
            return offset
        end
        if tcp and tvb:len() - offset < total then
            pinfo.desegment_offset = offset
            pinfo.desegment_len = total - (tvb:len() - offset)
            return tvb:len()
        end
        offset = offset + dissect_frame(tvb, pinfo, root, offset, header, total)
    end
    return offset
end

-- The heuristic: a known subheader, 4E's two zero bytes, and a length field that the bytes
-- present complete (exactly, over UDP).
local function heuristic(tvb, pinfo, root)
    if not mc3e.prefs.heuristic then return false end
    local header, total = frame_size(tvb, 0)
    if not header or not total or tvb:len() < header then return false end
    if header == 13 and tvb(4, 2):uint() ~= 0 then return false end
    local udp = pinfo.port_type ~= 2
    if (udp and total ~= tvb:len()) or (not udp and total > tvb:len()) then return false end
    local s = tvb(0, 2):uint()
    if (s == 0x5000 or s == 0x5400) and total - header < 6 then return false end
    if (s == 0xD000 or s == 0xD400) and total - header < 2 then return false end
    pinfo.conversation = mc3e
    mc3e.dissector(tvb, pinfo, root)
    return true
end

local registered_port = 0
local function register_port()
    local tcp, udp = DissectorTable.get("tcp.port"), DissectorTable.get("udp.port")
    if registered_port ~= 0 then
        tcp:remove(registered_port, mc3e)
        udp:remove(registered_port, mc3e)
    end
    registered_port = mc3e.prefs.port
    if registered_port ~= 0 then
        tcp:add(registered_port, mc3e)
        udp:add(registered_port, mc3e)
    end
end

function mc3e.prefs_changed()
    register_port()
end

register_port()
mc3e:register_heuristic("tcp", heuristic)
mc3e:register_heuristic("udp", heuristic)
